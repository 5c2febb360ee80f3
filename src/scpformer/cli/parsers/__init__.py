"""The parsers of the ``scpformer`` commands, built without importing the library.

Each module adds its commands' flags (see :mod:`scpformer.cli.commands` for the table of
commands) and names its handlers by ``"module:function"``, imported when the command runs
(:func:`scpformer.cli.commands.lazy_handler`): ``scpformer solve pdg6dof --help`` loads no
cvxpy, numba or torch.
"""
