"""Exceptions raised on bad input.

Every error the user can cause (missing file, malformed header, empty cloud, wrong units, a camera
inside the geometry, ...) is raised as a :class:`TpvpError` subclass with a message that names the
file or argument. The CLI prints the message on one line and exits with status 2 instead of showing
a traceback.
"""

import sys


class TpvpError(Exception):
    """Base class of all errors caused by input the user can fix."""

    exit_code = 2  # the command line's exit status for this error (docs/cli.md: exit status)


class InputFileError(TpvpError, OSError):
    """A file is missing, unreadable, truncated or malformed."""


class PointCloudError(TpvpError, ValueError):
    """A point cloud is empty, contains NaN/inf, or has implausible units."""


class ConfigError(TpvpError, ValueError):
    """An argument or configuration value is invalid."""


class BusyError(TpvpError):
    """The destination folder is being written by another run (its lock is held)."""

    exit_code = 3


class OutputWriteError(TpvpError, OSError):
    """Outputs could not be written (disk full, permissions); nothing was published."""

    exit_code = 4


class SensorError(TpvpError, ValueError):
    """A view cannot be rendered (camera inside the geometry, zero-length look-at, ...)."""


class GraphTooLargeError(PointCloudError):
    """A registration's deformation graph would exceed its node limit (``max_nodes``); the
    pipeline adds the previous session's file name to the message."""


def checked_cloud(points, name: str = "point cloud"):
    """``points`` as a float64 ``(N, 3)`` array; raises :class:`PointCloudError` naming ``name`` if
    it is not numeric, not ``(N, 3)``, empty or not finite."""
    import numpy as np

    try:
        points = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError):
        raise PointCloudError(f"{name} must be an (N, 3) array of numbers") from None
    if points.ndim != 2 or points.shape[1] != 3:
        raise PointCloudError(f"{name} must be an (N, 3) array, got shape {points.shape}")
    if len(points) == 0:
        raise PointCloudError(f"{name} is empty")
    if not np.all(np.isfinite(points)):
        raise PointCloudError(f"{name} contains NaN or infinite coordinates")
    return points


def run_command(args, name: str) -> int:
    """Run ``args.func(args)``; a TpvpError becomes one line ``<name>: error: ...`` on stderr and
    its exit status (2 bad input, 3 destination busy, 4 outputs not written), Ctrl-C one line saying
    whether the outputs were published and exit status 130 (docs/cli.md: exit status)."""
    try:
        return args.func(args)
    except TpvpError as exc:
        print(f"{name}: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt as exc:
        report = exc.report() if hasattr(exc, "report") else "interrupted before any output was written"
        print(f"{name}: {report}", file=sys.stderr)
        return 130


def install_warning_format(prog: str) -> None:
    """Print every Python warning as one line ``<prog>: warning: <message>`` on stderr: no module
    path, category or source line (a command line's user sees what to do, not where it was
    raised). ``warnings.warn`` calls, their filters and ``pytest.warns`` work as before."""
    import warnings

    def show(message, category, filename, lineno, file=None, line=None):
        stream = sys.stderr if file is None else file
        if stream is None:  # pythonw: no console
            return
        text = " ".join(str(message).split())  # one line whatever the message holds
        try:
            stream.write(f"{prog}: warning: {text}\n")
        except OSError:  # a closed or broken stderr must not turn a warning into an error
            pass

    warnings.showwarning = show
