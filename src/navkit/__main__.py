from navkit.cli.main import run

run()
