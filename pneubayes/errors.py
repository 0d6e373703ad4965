"""Exception hierarchy. Every message names the file, row, key or argument at fault."""


class PneubayesError(Exception):
    """Base class of all errors raised deliberately by pneubayes.

    Parameters
    ----------
    message : str
        What went wrong, naming the file, row, key or argument at fault.
    """


class RecordingError(PneubayesError, ValueError):
    """A recording (CSV + JSON pair) breaks the interchange contract.

    Parameters
    ----------
    problems : iterable of (str, str)
        Every problem found, each a ``(location, reason)`` pair where location names the
        file and the row or key; the message lists the first :attr:`MAX_LISTED`.

    Attributes
    ----------
    problems : list of (str, str)
        Every problem found, as given.
    """

    #: At most this many problems are spelled out in the message (all stay in .problems).
    MAX_LISTED = 25

    def __init__(self, problems):
        self.problems = list(problems)
        lines = [f"{loc}: {why}" for loc, why in self.problems[: self.MAX_LISTED]]
        more = len(self.problems) - len(lines)
        if more > 0:
            lines.append(f"... and {more} more problem(s) (see RecordingError.problems)")
        super().__init__("invalid recording:\n  " + "\n  ".join(lines))


class ParameterError(PneubayesError, ValueError):
    """A parameter value or name is missing, unknown or outside its bounds.

    Parameters
    ----------
    message : str
        The parameter's name, its value and the bounds or names allowed.
    """


class ModelCardError(PneubayesError, ValueError):
    """A model card (MODEL.json) cannot be read or does not describe a valid model.

    Parameters
    ----------
    message : str
        The card's file and the key at fault.
    """


class FormCombinationError(PneubayesError, ValueError):
    """A model combines forms the simulator cannot step together (two that each need
    the chamber's second state, a closure reading ports a tube puts out of reach, ...).

    Parameters
    ----------
    message : str
        The forms, and why they cannot be stepped together.
    """


class SimulationError(PneubayesError, RuntimeError):
    """The integrator failed.

    Parameters
    ----------
    message : str
        What failed: the parameter sets, or the span of time, and why.
    """


class RigCardError(PneubayesError, ValueError):
    """A rig card (``pneubayes-rig/1``) that breaks its contract; names the file and key."""


#: What a failed fit raises: a floating-point error in the refinement, the integrator's
#: failure, or forms the simulator cannot step together. The discovery loop records
#: any of them as that trial's failure and goes on.
FIT_FAILURES = (FloatingPointError, SimulationError, FormCombinationError)
