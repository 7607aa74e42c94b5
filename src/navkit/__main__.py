from navkit.cli.main import app

app()
