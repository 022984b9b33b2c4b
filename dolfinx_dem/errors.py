"""The errors of dolfinx_dem: every error the package raises derives from ``DEMError``; its one
warning, ``AccuracyWarning``, from ``UserWarning``.

Each class also derives from the built-in exception a Python user would expect there
(``ValueError`` for bad input, ``RuntimeError`` for a run that cannot go on, ...), so that
``except DEMError`` catches everything the package reports and ``except ValueError`` still
catches bad input.
"""

from __future__ import annotations


class DEMError(Exception):
    """The base class of every error of dolfinx_dem."""


class InputError(DEMError, ValueError):
    """Bad input: an argument, a mesh, a boundary condition, a material or a contact model that
    the package cannot use as given. Raised before anything is computed or written."""


class MissingFileError(InputError, FileNotFoundError):
    """A file the input names (a mesh, a scene, a series) does not exist."""


class SceneError(InputError):
    """A scene file or key is invalid; the message names the key."""


class CheckpointError(InputError):
    """There is no usable checkpoint, or it does not belong to this scene or mesh."""


class OutputFolderError(InputError):
    """The output folder cannot be used (it holds another run, or is not a folder)."""


class StateError(DEMError, RuntimeError):
    """A method was called out of order (e.g. ``MEMM.step`` before ``MEMM.initialise``) or on a
    state it does not hold (e.g. patch values gathered before a rebuild of the pair list)."""


class SolverError(DEMError, RuntimeError):
    """A solver did not converge (a linear solve, Newton, an eigenvalue solve)."""


class StaticsError(SolverError):
    """The energy minimisation of a static problem failed; the message names the likely cause."""


class InstabilityError(DEMError, RuntimeError):
    """The stability monitor of MEMM stopped a run; carries the step, time, a suggested time step
    and the monitor's reason (the message without the advice)."""

    def __init__(self, message: str, step: int, t: float, dt: float, suggested_dt: float, reason: str = ""):
        super().__init__(message)
        self.step, self.t, self.dt, self.suggested_dt, self.reason = step, t, dt, suggested_dt, reason


class UnresolvedContactError(DEMError, RuntimeError):
    """The contact between bodies is no longer resolved, and a run stops instead of going on
    with bodies passing through each other (collective: raised on every process alike): the
    contact surfaces interpenetrate by more than ``contact.max_penetration`` times the local
    candidate facet diameter, touching pairs lie deeper than the pair list radius, or a facet moves more
    than half its skin in one step."""


class OutputError(DEMError, OSError):
    """An output file could not be written or read back."""


class KernelMemoryError(DEMError, MemoryError):
    """A compiled kernel could not allocate its work arrays."""


class AccuracyWarning(UserWarning):
    """A discretisation choice that is known to give inaccurate results for this input (e.g. scheme B
    on a slender body): the run goes on, and the warning says what to change."""
