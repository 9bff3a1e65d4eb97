"""``python -m gisnoise``: the ``gisnoise`` command, for an environment whose scripts folder is not on the PATH."""

from gisnoise.cli.main import main

if __name__ == "__main__":  # pragma: no cover
    main()
