"""Subcommands of the ``uav_fusion`` command line tool.

Each module here exposes ``HELP`` (one line), ``add_arguments(parser)`` and
``run(args) -> int``; :mod:`uav_fusion.cli` lists them. Commands are thin: they parse
arguments and call the core.
"""
