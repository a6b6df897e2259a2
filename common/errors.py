"""The one exception tree of rollcam, and the exit status each error gives; every layer raises these.

It lives in ``rollcam.common`` because every layer (sim, firmware, emu, host) shares it. ``rollcam.host``
re-exports the classes. Exit statuses follow one rule (``exit_code``): 0 success, 2 bad usage or input
(``ConfigError``, ``SourceError``: a bad URI, option, value or file), 1 any other failure (a device that is not
there or failed, a protocol error, a missing optional package, an I/O error), 130 interrupted. A camera that is
not plugged in is a ``DeviceNotFoundError`` (exit 1), not bad input: the same command works once it is there.
"""

from __future__ import annotations


class RollcamError(Exception):
    """Root of every error rollcam raises on purpose."""


class ConfigError(RollcamError, ValueError):
    """A sensor description, scene option or other configuration is invalid."""


class SourceError(RollcamError):
    """A camera source cannot be opened or read (bad URI, missing backend, corrupt file)."""


class DeviceError(RollcamError):
    """An emulated or real device refused or failed an operation (no data, lost connection, busy)."""


class DeviceNotFoundError(DeviceError):
    """The device a well-formed source names is not there (unplugged, no such index or id, stream not running)."""


class ProtocolError(RollcamError):
    """A peer sent a malformed request on a control or transport protocol."""


class MissingDependencyError(RollcamError, ImportError):
    """An optional package a feature needs is not installed; the message names the package and its pip extra."""

    def __init__(self, package: str, extra: str | None = None, feature: str | None = None) -> None:
        self.package, self.extra, self.feature = package, extra, feature
        need = f"{feature} needs {package}" if feature else f"{package} is not installed"
        fix = f"pip install 'rollcam[{extra}]'" if extra else f"pip install {package}"
        super().__init__(f"{need} ({fix})")


def require(module: str, package: str | None = None, extra: str | None = None, feature: str | None = None):
    """Import and return ``module``, or raise ``MissingDependencyError`` naming ``package`` and ``extra``."""
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError as exc:
        if exc.name is not None and exc.name.split(".")[0] != module.split(".")[0]:
            raise  # the package is there but something it imports is broken: that is not a missing extra
        raise MissingDependencyError(package or module.split(".")[0], extra, feature) from None


EXIT_OK, EXIT_FAILURE, EXIT_USAGE, EXIT_INTERRUPTED = 0, 1, 2, 130


def exit_code(exc: BaseException) -> int:
    """The process exit status an error gives: 2 bad input (config, source), 130 Ctrl-C, 1 anything else."""
    if isinstance(exc, KeyboardInterrupt):
        return EXIT_INTERRUPTED
    if isinstance(exc, (ConfigError, SourceError)):
        return EXIT_USAGE
    return EXIT_FAILURE
