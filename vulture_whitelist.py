"""Names vulture (``make lint``, tests/core/test_dead_code.py) cannot see used.

Each line is a use vulture misses, with where it happens.
"""

plot_shapes  # cli/cmd_obstacles.py: `detect`'s option, read from the command's locals() (o["plot_shapes"])
