"""CLI subcommands: one module each, with ``register(subparsers)`` and ``run(args)``.

``register`` must stay light (argparse only); heavy imports go inside ``run``.
"""
