"""Exception hierarchy. Every message names the file, row, key or argument at fault."""


class PneubayesError(Exception):
    """Base class of all errors raised deliberately by pneubayes."""


class RecordingError(PneubayesError, ValueError):
    """A recording (CSV + JSON pair) breaks the interchange contract.

    ``problems`` holds every problem found, each a ``(location, reason)`` pair where
    location names the file and the row or key.
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
    """A parameter value or name is missing, unknown or outside its bounds."""


class ModelCardError(PneubayesError, ValueError):
    """A model card (MODEL.json) cannot be read or does not describe a valid model."""


class SimulationError(PneubayesError, RuntimeError):
    """The integrator failed; the message names the parameter sets that caused it."""


class RigCardError(PneubayesError, ValueError):
    """A rig card (``pneubayes-rig/1``) that breaks its contract; names the file and key."""
