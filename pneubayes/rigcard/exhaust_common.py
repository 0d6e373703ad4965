"""What every separate exhaust valve shares: its own command column, declared unit and
range, bound into the recording's ``exhaust_command`` column."""

from __future__ import annotations

from pneubayes.errors import RigCardError
from pneubayes.io.recording_format import EXHAUST_COMMAND_COLUMN
from pneubayes.rigcard.command import read_command
from pneubayes.rigcard.component import RigComponent


class SeparateExhaust(RigComponent):
    """Base of the ``exhaust`` kinds (options ``command`` and ``column``)."""

    @classmethod
    def option_keys(cls):
        return ("command", "column")

    @classmethod
    def read_options(cls, table, where):
        read_command(table.get("command"), f"{where} -> 'command'")  # checked here
        column = table.get("column", EXHAUST_COMMAND_COLUMN)
        if not (isinstance(column, str) and column.strip()):
            raise RigCardError(f"{where} key 'column': must be the name of the recording's "
                               f"column holding the exhaust command, got {column!r}")
        return {"command": dict(table["command"]), "column": column}

    @property
    def command(self):
        return read_command(self.extra["command"], f"exhaust {self.kind!r} -> 'command'")

    def metadata_defaults(self):
        return {}

    def bind_columns(self, recording, where):
        column = self.extra["column"]
        v = recording.extra_columns.get(column)
        if v is None:
            raise RigCardError(f"{where}: the exhaust valve's command column {column!r} is "
                               f"not in {recording.source} (its columns: "
                               f"{sorted(recording.extra_columns)})")
        try:
            v = v.astype(float)
        except ValueError:
            raise RigCardError(f"{where}: column {column!r} of {recording.source} is not "
                               "numeric") from None
        self.command.check(v, f"{recording.source} column {column!r}")
        extra = dict(recording.extra_columns)
        extra[EXHAUST_COMMAND_COLUMN] = v
        return {"extra_columns": extra}
