"""The ``rollcam`` command line."""


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``rollcam`` console script."""
    return 0
