"""Input signals: the signal algebra (:class:`Signal`, step, ramp, sine, chirp,
constant), CSV tables, the text syntax of the command line (:func:`parse_signal`; docs: simulate)
and the engineering units of the reports (:func:`format_quantity`).

The modules import one way: ``_signal`` (the algebra and quantities) <- ``_tables``
(CSV tables) <- ``_parse`` (the text syntax, which may name a table).
"""

from .._util._checks import decode_utf8
from ._format import (
    ENGINEERING,
    NOISE,
    column_unit,
    format_fixed,
    format_number,
    format_quantity,
    in_unit,
    is_noise,
    unit_text,
)
from ._parse import parse_signal
from ._signal import (
    KIND_OF_UNIT,
    SI_UNIT,
    UNITS,
    Signal,
    SignalError,
    check_signal,
    constant,
    log_grid,
    parse_list,
    parse_quantity,
    parse_range,
)
from ._tables import TIME_NAMES, read_text, table_header, table_rows, unit_scale, write_series

__all__ = ["Signal", "SignalError", "parse_signal", "parse_quantity", "parse_list", "parse_range", "log_grid",
           "check_signal", "constant", "read_text", "decode_utf8", "TIME_NAMES", "UNITS", "SI_UNIT", "KIND_OF_UNIT",
           "table_rows", "table_header", "unit_scale", "write_series", "ENGINEERING", "NOISE", "format_quantity",
           "format_number", "format_fixed", "unit_text", "column_unit", "in_unit", "is_noise"]
