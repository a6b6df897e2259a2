"""The one exception tree of rollcam, and the exit status each error gives; every layer raises these.

It lives in ``rollcam.common`` because every layer (sim, firmware, emu, host) shares it. ``rollcam.host``
re-exports the classes. Exit statuses follow one rule (``exit_code``): 0 success, 2 bad usage or input
(``ConfigError``, ``SourceError``: a bad URI, option, value or file), 1 any other failure (a device that is not
there or failed, a protocol error, a missing optional package, an I/O error), 130 interrupted. A camera that is
not plugged in is a ``DeviceNotFoundError`` (exit 1), not bad input: the same command works once it is there.
"""

from __future__ import annotations

import re
import shlex


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
    """A package a feature needs is not installed; the message names the package and how to install it.

    ``extra``: the pip extra that brings an optional package (``pip install 'rollcam[eval]'``). Without one, a
    package that is one of rollcam's own install dependencies (pyusb, pyserial, depthai, ...) is named as
    missing from a broken install; any other is named with its own ``pip install``.
    """

    def __init__(self, package: str, extra: str | None = None, feature: str | None = None) -> None:
        self.package, self.extra, self.feature = package, extra, feature
        need = f"{feature} needs {package}" if feature else f"{package} is not installed"
        fix = f"pip install {shlex.quote(package)}"
        if extra:
            fix = f"pip install 'rollcam[{extra}]'"
        elif is_install_dependency(package):
            need += ", an install dependency of rollcam missing from this broken install"
        super().__init__(f"{need} ({fix})")


def _project_name(requirement: str) -> str:
    """The normalised project name a requirement names (``'PyYAML>=6'`` -> ``'pyyaml'``)."""
    name = re.match(r"\s*([A-Za-z0-9][A-Za-z0-9._-]*)", requirement)
    return re.sub(r"[-_.]+", "-", name.group(1)).lower() if name else requirement


def is_install_dependency(package: str) -> bool:
    """True when ``package`` (a name or requirement) is one of the installed rollcam's own dependencies (not an
    extra's), read from its metadata, the one list (pyproject.toml's); False when rollcam is not installed."""
    from importlib.metadata import PackageNotFoundError, requires

    try:
        required = requires("rollcam") or []
    except PackageNotFoundError:
        return False
    return _project_name(package) in {_project_name(r) for r in required if ";" not in r}


def require(module: str, package: str | None = None, extra: str | None = None, feature: str | None = None):
    """Import and return ``module``, or raise ``MissingDependencyError`` naming ``package`` and ``extra`` (None
    for an install dependency)."""
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError as exc:
        if exc.name is not None and exc.name.split(".")[0] != module.split(".")[0]:
            raise  # the package is there but something it imports is broken: that is not a missing extra
        raise MissingDependencyError(package or module.split(".")[0], extra, feature) from None


EXIT_OK, EXIT_FAILURE, EXIT_USAGE, EXIT_INTERRUPTED = 0, 1, 2, 130


def is_interrupt(exc: BaseException) -> bool:
    """Whether ``exc`` is a Ctrl-C, or an error raised from or while handling one (compiled code a SIGINT
    interrupts reports a SystemError whose cause is the KeyboardInterrupt)."""
    seen: set[int] = set()
    e: BaseException | None = exc
    while e is not None and id(e) not in seen:
        if isinstance(e, KeyboardInterrupt):
            return True
        seen.add(id(e))
        e = e.__cause__ or e.__context__
    return False


def exit_code(exc: BaseException) -> int:
    """The process exit status an error gives: 2 bad input (config, source), 130 Ctrl-C, 1 anything else."""
    if is_interrupt(exc):
        return EXIT_INTERRUPTED
    if isinstance(exc, (ConfigError, SourceError)):
        return EXIT_USAGE
    return EXIT_FAILURE
