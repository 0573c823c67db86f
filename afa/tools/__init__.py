"""The text utilities that attach to a running system (``afa echo``, ``hz``, ``names``,
``poll``, ``sensor3d``, ``top``): command-line code over :mod:`afa.bridge`. See
``docs/tools.md``."""
