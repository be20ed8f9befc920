"""Timelines of event histories: ``slr plot`` and ``kb.plot`` (matplotlib, headless).

One row per event type: intervals as bars, points (start = end) as ticks; numeric arguments
(``values=["seg:2[0]"]``) as lines on axes of their own below the rows; complex events (the
types an event-rule engine derives) in their own color, with a diamond before the row label.

A history too long for the picture is aggregated in SQL before anything is drawn: when a type
has more events in the window than the plot has pixel columns (or than ``exact_limit``, when
given), its events are counted per pixel column
(``GROUP BY CAST((t - t0) / bin AS INTEGER)``) and the row shows how many events cover each
column (darker = more); a value line becomes the mean per column inside a min/max envelope.
The figure then holds a few artists per row whatever the number of events, so a million
events draw in about a second (``benchmarks/bench_plot.py``).

The module reads the store only through ``source.sql(query, params)`` — a
:class:`slr_sql.KnowledgeBase`, an :class:`slr_sql.store.EventStore`, or anything with that
method — so the knowledge base can offer it as ``kb.plot`` without an import cycle.
matplotlib is imported only when a figure is made (the ``slr_sql[plot]`` extra), and only its
object-oriented API with the Agg canvas: no pyplot, no display, no global backend change.

>>> import slr_sql
>>> from slr_sql.plot import timeline
>>> kb = slr_sql.open(clock=slr_sql.ManualClock(0))
>>> kb.add("move(r1)^[2, 8]"); kb.add("bump(r1)^5")
>>> fig = timeline(kb, start=0, end=10, size=(600, 200))
>>> [row.label for row in fig.slr_timeline.rows], fig.get_size_inches().tolist()
(['bump/1', 'move/1'], [6.0, 2.0])
>>> kb.close()
"""
from __future__ import annotations

import math
import re
import time
from dataclasses import dataclass, field
from typing import Any, Iterable

from .arguments import check_time_option
from .errors import SLRError, SLRTimeout
from .store.timeline import Statement, TimelineStatements, timeline_statements
from .store import DatabaseError, quote_identifier
from .printable import printable_name, printable_text, shown

__all__ = [
    "timeline", "collect_timeline", "draw_timeline", "save_timeline", "parse_value_spec",
    "parse_size", "Timeline", "TypeRow", "ValueSeries", "EventTypeRef", "ValueSpec",
    "INSTALL_HINT", "DEFAULT_WIDTH", "DEFAULT_DPI", "UndrawableRange", "MAX_DRAWN",
]

INSTALL_HINT = "plots need matplotlib: pip install 'slr_sql[plot]'"
DEFAULT_WIDTH = 1200         # pixels
DEFAULT_DPI = 100
MAX_PIXELS = 20000           # per side: beyond this a PNG is a mistake, not a picture
# Times and values beyond this magnitude are refused: matplotlib's limits and ticks work on
# spans and multiples of them, which overflow near the largest float
MAX_DRAWN = 1e306
LAST_DATE = 253_402_300_799.0   # 9999-12-31 23:59:59 UTC: the last time a datetime can name

# Colors: intervals blue, points near-black, complex events red, values purple.
INTERVAL_COLOR = "#1f77b4"
POINT_COLOR = "#222222"
COMPLEX_COLOR = "#d62728"
VALUE_COLOR = "#6a3d9a"
COMPLEX_MARK = "\u25c6 "     # ◆ before the label of a complex event type

FONT_PT = 9.0
BAR_HALF = 0.32              # half the height of an interval bar, in row units
TICK_HALF = 0.42             # half the height of a point tick
MAX_LANES = 6                # overlapping intervals of a row are stacked in up to this many lanes


class UndrawableRange(SLRError):
    """Times or values a figure cannot draw: a window too wide, or a magnitude beyond
    :data:`MAX_DRAWN`."""


# ---------------------------------------------------------------------------------------------
# What to draw
# ---------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class EventTypeRef:
    """One event type of the store and the table holding its events."""

    name: str
    arity: int
    table: str

    @property
    def label(self) -> str:
        return f"{self.name}/{self.arity}"


@dataclass(frozen=True)
class ValueSpec:
    """A numeric argument to draw: ``seg:2``, ``seg/2:arg2``, ``tf:3.pose[0][0]``.

    ``argument`` is the 1-based argument index; ``path`` a JSON path inside that argument
    (``$[0]``, ``$.pose[0][0]``) for lists and compound terms, or None for the whole argument.
    """

    type_text: str
    argument: int | None
    path: str | None
    text: str


@dataclass
class TypeRow:
    """The data of one timeline row. ``mode`` is ``"exact"`` (every event: ``intervals`` as
    (start, end) pairs, ``points`` as times) or ``"binned"`` (``coverage[i]`` = intervals
    overlapping pixel column i, ``point_counts[i]`` = points falling in it)."""

    type: EventTypeRef
    complex: bool
    count: int
    mode: str
    intervals: list[tuple[float, float]] = field(default_factory=list)
    points: list[float] = field(default_factory=list)
    coverage: Any = None
    point_counts: Any = None
    key: str | None = None          # the --by value this row holds (None: every event)
    color: str | None = None        # the key's color (None: by kind)
    # (end time, arrival time) of each event that arrived after it happened (exact rows)
    lags: list[tuple[float, float]] = field(default_factory=list)

    @property
    def label(self) -> str:
        return self.type.label if self.key is None else f"{self.type.label} {self.key}"


@dataclass
class QueryRow:
    """A goal's answers over time (``--query 'location(cup1, L)^T' --every 0.1``): the goal
    asked with T at each sample time; ``runs`` are (start, end, answer text) of consecutive
    samples with the same answer (text ``None``: no answer)."""

    goal: str
    every: float
    samples: int
    runs: list[tuple[float, float, str | None]] = field(default_factory=list)
    colors: dict[str, str] = field(default_factory=dict)

    @property
    def label(self) -> str:
        return self.goal


@dataclass
class ValueSeries:
    """The data of one value axes: ``times``/``values`` (exact: one sample per event, at its
    end time) or per pixel column ``times`` (column centres), ``values`` (mean), ``lows`` and
    ``highs`` (binned)."""

    spec: ValueSpec
    type: EventTypeRef
    complex: bool
    count: int
    mode: str
    times: list[float] = field(default_factory=list)
    values: list[float] = field(default_factory=list)
    lows: list[float] = field(default_factory=list)
    highs: list[float] = field(default_factory=list)
    # split per key (the --by argument, or the first argument naming the object): one line
    # each, as (key, color, times, values); ``times``/``values`` above stay the whole series
    lines: list[tuple[str, str, list[float], list[float]]] = field(default_factory=list)


@dataclass
class Timeline:
    """Everything a figure shows, read from the store; drawing needs nothing else."""

    start: float
    end: float
    width: int
    height: int
    dpi: int
    bins: int
    left: float                     # axes placement, as fractions of the figure
    right: float
    top: float
    bottom: float
    rows: list[TypeRow]
    series: list[ValueSeries]
    title: str
    origin: float = 0.0             # the time axis shows t - origin (epoch-second data)
    queries: list[QueryRow] = field(default_factory=list)

    @property
    def bin_width(self) -> float:
        return (self.end - self.start) / self.bins


# ---------------------------------------------------------------------------------------------
# Parsing options
# ---------------------------------------------------------------------------------------------

_VALUE_SPEC = re.compile(
    r"(?P<type>[^:]+):(?:arg)?(?P<index>[0-9]+)(?P<path>(?:\[[0-9]+\]|\.[A-Za-z_$][A-Za-z0-9_$]*)*)\Z")


def parse_value_spec(text: str) -> ValueSpec:
    """``TYPE:ARG[PATH]`` as a :class:`ValueSpec`. ARG is the argument's index (from 1) or its
    column name (``arg2``); PATH reaches into a list or compound argument.

    >>> parse_value_spec("tf/3:3.pose[0][0]")
    ValueSpec(type_text='tf/3', argument=3, path='$.pose[0][0]', text='tf/3:3.pose[0][0]')
    >>> parse_value_spec("seg:arg2[1]").path
    '$[1]'
    """
    match = _VALUE_SPEC.match(text.strip()) if isinstance(text, str) else None
    if match is None:
        raise SLRError(f"bad value {text!r}: expected TYPE:ARG with ARG an argument index or "
                       "column name and an optional path into it, e.g. speed:1, seg:2[0], "
                       "tf:3.pose[0][0]")
    index = int(match.group("index"))
    if index < 1:
        raise SLRError(f"bad value {text!r}: arguments are numbered from 1")
    path = match.group("path")
    return ValueSpec(match.group("type").strip(), index, "$" + path if path else None, text.strip())


def parse_size(text: str) -> tuple[int, int | None]:
    """``"1200x400"`` → (1200, 400); ``"1200"`` or ``"1200x"`` → (1200, None): the height
    follows from the number of rows.

    >>> parse_size("800x300"), parse_size("640")
    ((800, 300), (640, None))
    """
    match = re.fullmatch(r"\s*([0-9]+)\s*(?:[xX×]\s*([0-9]*)\s*)?", text or "")
    if match is None:
        raise SLRError(f"bad size {text!r}: expected WIDTHxHEIGHT in pixels, e.g. 1200x400")
    return int(match.group(1)), int(match.group(2)) if match.group(2) else None


def _check_pixels(what: str, value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not 16 <= value <= MAX_PIXELS:
        raise SLRError(f"the {what} must be a whole number of pixels between 16 and {MAX_PIXELS}, "
                       f"not {value!r}")
    return value


def _check_time(what: str, value: Any) -> float | None:
    if value is None:
        return None
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise SLRError(f"{what} must be a number, not {shown(value)}") from None
    except OverflowError:    # an integer beyond any float
        number = math.inf
    if not math.isfinite(number):
        raise SLRError(f"{what} must be a finite number, not {shown(value)}")
    return number


# ---------------------------------------------------------------------------------------------
# Reading the store
# ---------------------------------------------------------------------------------------------

def _statements(source: Any) -> TimelineStatements:
    """The statements for the source's database: a local knowledge base's dialect, else
    SQLite's (what a store served by ``slr serve`` speaks)."""
    return timeline_statements(getattr(getattr(source, "store", None), "dialect", None))


def _rows(source: Any, statement: Statement) -> list[tuple]:
    query, params = statement
    try:
        return list(source.sql(query, tuple(params))[1])
    except DatabaseError as exc:  # locked, busy, unreadable file: say it in words
        raise SLRError(f"reading the store for the plot failed: {exc}") from None
    except SLRError as exc:
        if type(exc) is not SLRError:  # SLRBusy, SLRTimeout...: the caller may act on the kind
            raise
        raise SLRError(f"reading the store for the plot failed: {exc}") from None


def store_types(source: Any) -> list[EventTypeRef]:
    """Every event type in the store's catalog (``slr_event_types``), by name and arity.

    >>> import slr_sql
    >>> kb = slr_sql.open(clock=slr_sql.ManualClock(0)); kb.add("move(r1)^[2, 8]"); kb.add("bump(r1)^5")
    >>> [(ref.name, ref.arity) for ref in store_types(kb)]
    [('bump', 1), ('move', 1)]
    """
    rows = _rows(source, _statements(source).event_types())
    return [EventTypeRef(str(name), int(arity), str(table)) for name, arity, table in rows]


def _split_type(text: str) -> tuple[str, int | None]:
    """``name/arity`` or ``name`` (a quoted name read as Prolog reads it).

    >>> _split_type(" seg/2 "), _split_type("'x/seen'/2"), _split_type("tf")
    (('seg', 2), ('x/seen', 2), ('tf', None))
    """
    from .parser import parse_indicator

    return parse_indicator(text.strip())


def _known_types(catalog: list[EventTypeRef]) -> str:
    r"""The store's event types for a message, each name as the terminal draws it (a name's
    line break was a line of the message of its own).

    >>> print(_known_types([EventTypeRef("seg", 2, "seg"), EventTypeRef("a\nb", 1, "t")]))
    seg/2, 'a\nb'/1
    """
    return ", ".join(f"{printable_name(t.name)}/{t.arity}" for t in catalog) or "none"


def _resolve_types(catalog: list[EventTypeRef], texts: Iterable[str]) -> list[EventTypeRef]:
    chosen: list[EventTypeRef] = []
    for text in texts:
        if not isinstance(text, str) or not text.strip():
            raise SLRError(f"an event type is a name or name/arity, not {text!r}")
        name, arity = _split_type(text)
        found = [t for t in catalog if t.name == name and (arity is None or t.arity == arity)]
        if not found:
            raise SLRError(f"unknown event type: {printable_name(text.strip())} (the store "
                           f"has: {_known_types(catalog)})")
        chosen.extend(t for t in found if t not in chosen)
    return chosen


def _type_matches(ref: EventTypeRef, names: set[str]) -> bool:
    return ref.name in names or ref.label in names


def _complex_names(source: Any, complex_types: Iterable[str] | None) -> set[str]:
    """The names (``p`` or ``p/N``) of complex event types. Given explicitly, or asked of
    the source: an event-rule engine that stores derived events offers
    ``complex_event_types()`` (an iterable of such names) on the knowledge base."""
    if complex_types is None:
        hook = getattr(source, "complex_event_types", None)
        rules = getattr(source, "event_rules", None)
        if callable(hook):
            complex_types = hook()
        elif callable(rules):   # the heads of the event rules in force derive complex events
            complex_types = [str(rule.get("head")) for rule in rules() if rule.get("head")]
        else:
            complex_types = ()
    if isinstance(complex_types, str):
        complex_types = [complex_types]
    return {str(name).strip() for name in complex_types}


def _window(source: Any, types: list[EventTypeRef], start: float | None,
            end: float | None) -> tuple[float, float, float]:
    """The time window: as given, or the span of the events of ``types`` with a margin; and
    where the data starts (the window's start when given)."""
    lo, hi = start, end
    first_event = lo
    edges = [t for t in (lo, hi) if t is not None]   # what the window is made of
    if lo is None or hi is None:
        firsts, lasts = [], []
        store = getattr(source, "store", None)
        for t in types:
            table = quote_identifier(t.table)
            if store is not None:   # (a local store: its earliest start read from an index)
                store.ensure_start_order(t.name, t.arity)
            first = _rows(source, _statements(source).time_span_first(table))[0][0]
            last = _rows(source, _statements(source).time_span_last(table))[0][0]
            if first is not None:
                firsts.append(float(first))
                lasts.append(float(last))
        data_lo = min(firsts) if firsts else 0.0
        data_hi = max(lasts) if lasts else 1.0
        if lo is not None and hi is None:
            data_lo = lo
            data_hi = max(data_hi, lo)
        if hi is not None and lo is None:
            data_hi = hi
            data_lo = min(data_lo, hi)
        edges += [data_lo, data_hi]
        span = data_hi - data_lo
        first_event = data_lo if lo is None else lo
        margin = span * 0.02 if span > 0 else max(abs(data_hi) * 0.02, 0.5)
        lo = data_lo - margin if lo is None else lo
        hi = data_hi + margin if hi is None else hi
    if not lo < hi:
        raise SLRError(f"empty time window: from {lo:g} to {hi:g} (from must be before to)")
    if not math.isfinite(hi - lo):
        raise UndrawableRange(f"the time window from {lo:g} to {hi:g} is too wide to draw")
    if not all(-MAX_DRAWN <= t <= MAX_DRAWN for t in edges):
        raise UndrawableRange(f"the time window from {lo:g} to {hi:g} is beyond what a plot can "
                              f"draw (times within ±{MAX_DRAWN:g}); choose one with --from/--to")
    return float(lo), float(hi), float(first_event if first_event is not None else lo)


def _collect_row(source: Any, ref: EventTypeRef, is_complex: bool, lo: float, hi: float,
                 bins: int, exact_limit: int, key: tuple[int, Any, str] | None = None,
                 lags: bool | None = None) -> TypeRow:
    table = quote_identifier(ref.table)
    statements = _statements(source)
    # --by: only the events whose argument holds the key (stored value, label)
    only: tuple[str | None, Any] = (None, None)
    if key is not None:
        only = (quote_identifier(f"arg{key[0]}"), key[1])
    # Read the events themselves, up to one more than fits: that answers "exact or binned?"
    # without a count(*) over a long history.
    events = _rows(source, statements.events(table, lo, hi, exact_limit + 1, *only))
    if len(events) <= exact_limit:
        row = TypeRow(ref, is_complex, len(events), "exact",
                      key=None if key is None else key[2])
        for s, e, _ in events:
            if s == e:
                row.points.append(float(s))
            else:
                row.intervals.append((float(s), float(e)))
        arrivals = [(float(e), float(a)) for _, e, a in events if a is not None]
        # Arrival times come from the store's clock; they say something about the events only
        # when that clock is the events' own (a live robot), not an import's wall clock.
        span = hi - lo
        same_clock = all(lo - span <= a <= hi + span for _, a in arrivals)
        if lags or (lags is None and same_clock):
            row.lags = [(e, a) for e, a in arrivals if a > e]
        return row

    try:
        import numpy as np  # comes with matplotlib; only the binned path needs it
    except ImportError:
        raise SLRError(INSTALL_HINT) from None

    bin_width = (hi - lo) / bins
    starts = np.zeros(bins + 1, dtype=np.int64)
    ends = np.zeros(bins + 1, dtype=np.int64)
    point_counts = np.zeros(bins, dtype=np.int64)
    # Per pixel column: how many points fall in it, and where the intervals start and end.
    # The intervals covering column i are those started at or before i and not ended before i.
    for b, is_point, n in _rows(source, statements.start_bins(table, lo, hi, bin_width, *only)):
        b = min(int(b), bins - 1)
        if is_point:
            point_counts[b] += n
        else:
            starts[b] += n
    if starts.any():
        for b, n in _rows(source, statements.end_bins(table, lo, hi, bin_width, *only)):
            ends[min(int(b), bins - 1) + 1] += n
    # (two statements: an interval added in between could end without having started)
    coverage = np.maximum(np.cumsum(starts)[:bins] - np.cumsum(ends)[:bins], 0)
    count = int(starts.sum() + point_counts.sum())
    return TypeRow(ref, is_complex, count, "binned", coverage=coverage, point_counts=point_counts,
                   key=None if key is None else key[2])


def _resolve_value(catalog: list[EventTypeRef], spec: ValueSpec) -> EventTypeRef:
    name, arity = _split_type(spec.type_text)
    found = [t for t in catalog if t.name == name and (arity is None or t.arity == arity)]
    if not found:
        raise SLRError(f"bad value {spec.text!r}: unknown event type "
                       f"{printable_name(spec.type_text)} (the store has: "
                       f"{_known_types(catalog)})")
    fitting = [t for t in found if t.arity >= spec.argument]
    if not fitting:
        raise SLRError(f"bad value {spec.text!r}: {found[0].label} has {found[0].arity} "
                       f"argument{'s' if found[0].arity != 1 else ''}, not {spec.argument}")
    if len(fitting) > 1:
        raise SLRError(f"bad value {spec.text!r}: {name} has several arities "
                       f"({', '.join(t.label for t in fitting)}); write {fitting[0].label}:...")
    return fitting[0]


# one color per key: neither the complex events' red nor the arrival lags' orange
PALETTE = ["#1f77b4", "#2ca02c", "#9467bd", "#8c564b", "#e377c2", "#17becf", "#bcbd22",
           "#7f7f7f", "#393b79", "#637939", "#843c39", "#3182bd"]
MAX_KEYS = len(PALETTE)
LAG_COLOR = "#ff7f0e"


def _distinct(source: Any, ref: EventTypeRef, argument: int, lo: float,
              hi: float) -> list[tuple]:
    """Up to MAX_KEYS + 1 distinct values of an argument in the window, in order."""
    return _rows(source, _statements(source).distinct(
        quote_identifier(ref.table), quote_identifier(f"arg{argument}"), lo, hi, MAX_KEYS + 1))


def _keys(source: Any, ref: EventTypeRef, argument: int, lo: float, hi: float,
          what: str) -> list[tuple[Any, str]]:
    """The distinct values of an argument in the window, as (stored value, label)."""
    values = _distinct(source, ref, argument, lo, hi)
    if len(values) > MAX_KEYS:
        raise SLRError(f"{what}: argument {argument} of {ref.label} has more than {MAX_KEYS} "
                       f"values in the window; choose fewer with --from/--to or another argument")
    return [(v, str(v)) for (v,) in values]


def _collect_series(source: Any, spec: ValueSpec, ref: EventTypeRef, is_complex: bool,
                    lo: float, hi: float, bins: int, exact_limit: int,
                    split: int | None = None, colors: dict[str, str] | None = None
                    ) -> ValueSeries:
    table = quote_identifier(ref.table)
    column = quote_identifier(f"arg{spec.argument}")
    key_column = quote_identifier(f"arg{split}") if split is not None else None
    statements = _statements(source)
    samples = _rows(source, statements.samples(table, column, spec.path, key_column, lo, hi,
                                               exact_limit + 1))
    if len(samples) <= exact_limit:
        series = ValueSeries(spec, ref, is_complex, len(samples), "exact")
        series.times = [float(t) for t, _, _ in samples]
        series.values = [float(v) for _, v, _ in samples]
        if split is not None:   # one line per object, never one line through several
            by_key: dict[str, tuple[list[float], list[float]]] = {}
            for t, v, k in samples:
                times, values = by_key.setdefault(str(k), ([], []))
                times.append(float(t))
                values.append(float(v))
            colors = colors or {}
            for i, (k, (times, values)) in enumerate(sorted(by_key.items())):
                series.lines.append((k, colors.get(k, PALETTE[i % MAX_KEYS]), times, values))
    else:
        bin_width = (hi - lo) / bins
        series = ValueSeries(spec, ref, is_complex, 0, "binned")
        for b, low, high, mean, n in _rows(
                source, statements.value_bins(table, column, spec.path, lo, hi, bin_width)):
            b = min(int(b), bins - 1)
            series.times.append(lo + (b + 0.5) * bin_width)
            series.values.append(float(mean))
            series.lows.append(float(low))
            series.highs.append(float(high))
            series.count += int(n)
    # no numeric value but events in the window: one of their values, for the message
    first = _rows(source, statements.first_value(table, column, spec.path, lo, hi)) \
        if not series.count else []
    if first:
        sample = first if first[0][0] is not None else []
        seen = f" (e.g. {sample[0][0]})" if sample else ""
        hint = ("; give a path into it, e.g. "
                f"{spec.type_text}:{spec.argument}[0]" if sample and str(sample[0][0])[:1] in "[{"
                else "")
        raise SLRError(f"bad value {spec.text!r}: argument {spec.argument} of {ref.label} has "
                       f"no numeric values between {lo:g} and {hi:g}{seen}{hint}")
    _check_drawable(series)
    return series


def _check_drawable(series: ValueSeries) -> None:
    """Refuse (:class:`UndrawableRange`) a value line with a value beyond ``MAX_DRAWN``."""
    near = "near " if series.mode == "binned" else ""
    columns = [(series.times, series.values), (series.times, series.lows),
               (series.times, series.highs)]
    columns += [(times, values) for _, _, times, values in series.lines]
    for times, values in columns:
        for t, v in zip(times, values):
            if not -MAX_DRAWN <= v <= MAX_DRAWN:
                raise UndrawableRange(
                    f"bad value {series.spec.text!r}: {v:g} {near}at t={t:g} is beyond what a "
                    f"plot can draw (values within ±{MAX_DRAWN:g}); choose a window without it "
                    f"with --from/--to")


def _horizontal(width: int, dpi: int, labels: list[str]) -> tuple[float, float]:
    """Left and right edges of the axes (fractions of the figure width), from sizes in points
    so that they hold at any dpi: room for the longest row label on the left."""
    font_px = FONT_PT * dpi / 72.0
    longest = max((len(label) for label in labels), default=4)
    left_px = min(max(24 + 0.62 * font_px * (longest + 2), 8 * font_px), 0.45 * width)
    right_px = 2.2 * font_px
    return left_px / width, 1 - right_px / width


def _vertical(height: int | None, dpi: int, n_rows: int, n_series: int,
              has_title: bool) -> tuple[int, float, float]:
    """Figure height (when not given: enough for the rows and value axes) and the top and
    bottom edges of the axes: room for the title and legend above, the time axis below."""
    font_px = FONT_PT * dpi / 72.0
    top_px = (4.6 if has_title else 3.0) * font_px
    bottom_px = 4.0 * font_px
    if height is None:
        inner = (max(n_rows, 1) * 3.2 + n_series * 12.0) * font_px
        height = min(int(round(max(top_px + bottom_px + inner, 12 * font_px))), MAX_PIXELS)
    return height, 1 - top_px / height, bottom_px / height


EPOCH_2001 = 978_307_200.0   # a window starting after this is Unix time: drawn relative
MAX_SAMPLES = 5000           # times a --query is asked


def _by_specs(source_types: list[EventTypeRef], by: Iterable[str]) -> dict[EventTypeRef, int]:
    """``--by seg:1`` → {seg/2: 1}: which argument splits the rows of which type."""
    out: dict[EventTypeRef, int] = {}
    for text in by:
        spec = parse_value_spec(text)
        if spec.path is not None:
            raise SLRError(f"bad --by {text!r}: an argument, TYPE:ARG, without a path")
        ref = _resolve_value(source_types, spec)
        out[ref] = spec.argument
    return out


def _term_text(value: Any) -> str:
    """An answer value as Prolog text (answers give strings as ``str``)."""
    from .terms import String, format_term

    return format_term(String(value) if type(value) is str else value)


def _collect_query(source: Any, goal: str, every: float, lo: float, hi: float,
                   timeout: float | None = None) -> QueryRow:
    """Ask ``goal`` (with a variable T for the time) at lo, lo + every, ... <= hi; all the
    asks within ``timeout`` seconds together (each one is given the time that is left)."""
    if not callable(getattr(source, "query", None)):
        raise SLRError("a --query plot needs a knowledge base (kb.plot), not a bare store")
    every = _check_time("every", every)
    if every is None or every <= 0:
        raise SLRError(f"--every must be a positive number of seconds, not {every!r}")
    steps = (hi - lo) / every + 1e-9   # (inf when every is tiny)
    samples = math.floor(steps) + 1.0 if math.isfinite(steps) else math.inf
    if not samples <= MAX_SAMPLES:
        said = f"{samples:.3g}" if math.isfinite(samples) else "more than 1e+308"
        raise SLRError(f"--every {every:g} asks the goal {said} times between {lo:g} and "
                       f"{hi:g}; at most {MAX_SAMPLES}: a larger --every or a shorter window")
    n = int(samples)
    # the timeout= of kb.query, checked alike: inf (1e400) is no limit, NaN and < 0 are none
    check_time_option("timeout", timeout, minimum=0.0)
    seconds = None if timeout is None else float(timeout)
    deadline = None if seconds is None or seconds == math.inf else time.monotonic() + seconds
    row = QueryRow(goal, every, n)
    for i in range(n):
        t = lo + i * every
        left = None if deadline is None else deadline - time.monotonic()
        try:
            if left is not None and left <= 0:
                raise SLRTimeout("no time left")
            answers = source.query(goal, args={"T": t}, **({} if left is None
                                                           else {"timeout": left}))
        except SLRTimeout:
            if deadline is None:
                raise
            raise SLRTimeout(f"--query {goal}: the timeout of {seconds:g} s ran out at T = "
                             f"{t:g}, its ask {i + 1} of {n}; a larger --every, a shorter "
                             f"window or a longer --timeout") from None
        text = None
        if answers:
            shown = [f"{name} = {_term_text(value)}" for name, value in answers[0].items()
                     if name != "T"]
            text = ", ".join(shown) or "true"
            if len(answers) > 1:
                text += f" (+{len(answers) - 1})"
        end = t + every
        if row.runs and row.runs[-1][2] == text and abs(row.runs[-1][1] - t) < every / 2:
            row.runs[-1] = (row.runs[-1][0], end, text)
        else:
            row.runs.append((t, end, text))
    for text in dict.fromkeys(r[2] for r in row.runs if r[2] is not None):
        row.colors[text] = PALETTE[len(row.colors) % MAX_KEYS]
    return row


def _texts(option: str, value: Any) -> list:
    """An option of one text or a list of them as a list, else an :class:`SLRError` (a
    number is no list of event types).

    >>> _texts("types", "p/1"), _texts("types", ("p", "q/2"))
    (['p/1'], ['p', 'q/2'])
    >>> _texts("types", 5)
    Traceback (most recent call last):
    ...
    slr_sql.errors.SLRError: plot: types must be a text or a list of texts, not 5
    """
    if isinstance(value, str):
        return [value]
    try:
        return list(value)
    except TypeError:
        raise SLRError(f"plot: {option} must be a text or a list of texts, not "
                       f"{shown(value)}") from None


def collect_timeline(source: Any, types: Iterable[str] | str | None = None, *,
                     start: float | None = None, end: float | None = None,
                     values: Iterable[str] | str = (),
                     complex_types: Iterable[str] | None = None,
                     size: tuple[int, int | None] | None = None, dpi: int = DEFAULT_DPI,
                     title: str | None = None, exact_limit: int | None = None,
                     by: Iterable[str] | str = (), lags: bool | None = None,
                     internal: bool = False, relative: bool | None = None,
                     query: str | None = None, every: float | None = None,
                     timeout: float | None = None) -> Timeline:
    """Read what :func:`timeline` draws, without drawing (no matplotlib needed unless a row is
    binned, which uses numpy). Arguments as for :func:`timeline`.

    >>> import slr_sql
    >>> kb = slr_sql.open(clock=slr_sql.ManualClock(0)); kb.add("move(r1)^[2, 8]")
    >>> row = collect_timeline(kb, start=0, end=10).rows[0]
    >>> row.label, row.mode, row.intervals
    ('move/1', 'exact', [(2.0, 8.0)])
    >>> kb.close()
    """
    types = None if types is None else _texts("types", types)
    values = _texts("values", values)
    width, height = size if size is not None else (DEFAULT_WIDTH, None)
    width = _check_pixels("width", width)
    if height is not None:
        height = _check_pixels("height", height)
    if isinstance(dpi, bool) or not isinstance(dpi, int) or not 10 <= dpi <= 1000:
        raise SLRError(f"dpi must be a whole number between 10 and 1000, not {dpi!r}")
    if exact_limit is not None and (isinstance(exact_limit, bool)
                                    or not isinstance(exact_limit, int) or exact_limit < 0):
        raise SLRError(f"exact_limit must be a whole number >= 0, not {exact_limit!r}")
    lo, hi = _check_time("from", start), _check_time("to", end)
    if lo is not None and hi is not None and not lo < hi:
        raise SLRError(f"empty time window: from {lo:g} to {hi:g} (from must be before to)")
    specs = [parse_value_spec(text) for text in values]

    by = _texts("by", by)
    catalog = store_types(source)
    complex_names = _complex_names(source, complex_types)
    value_types = [_resolve_value(catalog, spec) for spec in specs]
    split_by = _by_specs(catalog, by)
    chosen = _resolve_types(catalog, types) if types is not None else None
    if chosen is None and not internal:   # the store's own bookkeeping (slr_import/3, ...)
        catalog = [t for t in catalog if not t.name.startswith("slr_")]
    window_types = (chosen if chosen is not None else catalog) + value_types
    lo, hi, first_event = _window(source, window_types, lo, hi)
    if relative is None:
        relative = EPOCH_2001 <= lo and hi <= LAST_DATE   # Unix time with a calendar date
    origin = float(math.floor(first_event)) if relative else 0.0

    candidates = chosen if chosen is not None else catalog
    left, right = _horizontal(width, dpi, [COMPLEX_MARK + t.label + " " * 10 for t in candidates]
                              + [s.text for s in specs] + ([query] if query else []))
    bins = max(1, int(round(width * (right - left))))  # one bin per pixel column of the axes
    if exact_limit is None:  # aggregate what does not fit the pixels
        exact_limit = bins
    rows = []
    key_colors: dict[str, str] = {}
    for ref in candidates:
        is_complex = _type_matches(ref, complex_names)
        if ref in split_by:
            for value, label in _keys(source, ref, split_by[ref], lo, hi, "--by"):
                row = _collect_row(source, ref, is_complex, lo, hi, bins, exact_limit,
                                   key=(split_by[ref], value, label), lags=lags)
                row.color = key_colors.setdefault(label, PALETTE[len(key_colors) % MAX_KEYS])
                rows.append(row)
            continue
        row = _collect_row(source, ref, is_complex, lo, hi, bins, exact_limit, lags=lags)
        if row.count or chosen is not None:  # by default, only types with events in the window
            rows.append(row)
    series = []
    for spec, ref in zip(specs, value_types):
        split = split_by.get(ref)
        if split is None and ref.arity > 1 and spec.argument != 1:
            # the first argument names the object (seg(cup1, ..)): a line per object when
            # there are a few, never one line zigzagging through several
            split = 1 if 1 < len(_distinct(source, ref, 1, lo, hi)) <= MAX_KEYS else None
        series.append(_collect_series(source, spec, ref, _type_matches(ref, complex_names),
                                      lo, hi, bins, exact_limit, split=split,
                                      colors=key_colors))
    queries = [] if query is None else [_collect_query(source, query, every, lo, hi, timeout)]
    height, top, bottom = _vertical(height, dpi, len(rows) + len(queries), len(series),
                                    bool(title))
    # (a title from a file name or an argument that is no UTF-8 holds lone surrogates, which
    # matplotlib cannot draw: "TypeError: set_text(): incompatible function arguments")
    return Timeline(lo, hi, width, height, dpi, bins, left, right, top, bottom, rows, series,
                    printable_text(title) if title else "", origin, queries)


# ---------------------------------------------------------------------------------------------
# Drawing
# ---------------------------------------------------------------------------------------------

def _matplotlib() -> Any:
    try:
        import matplotlib  # noqa: F401
        from matplotlib.figure import Figure
        from matplotlib.backends.backend_agg import FigureCanvasAgg
    except ImportError:
        raise SLRError(INSTALL_HINT) from None
    return Figure, FigureCanvasAgg


def _density_alpha(counts: Any) -> Any:
    """0 where nothing is, 0.3..1 growing with the logarithm of the count elsewhere."""
    import numpy as np

    counts = np.asarray(counts, dtype=float)
    top = counts.max() if counts.size else 0.0
    if top <= 0:
        return np.zeros_like(counts)
    scale = np.log1p(counts) / math.log1p(top)
    return np.where(counts > 0, 0.3 + 0.7 * scale, 0.0)


def _lanes(intervals: list[tuple[float, float]]) -> list[int]:
    """A lane for each interval (in the order given) so that overlapping intervals of one row
    sit one above the other: the first lane free at its start, at most MAX_LANES lanes (the
    rest share the last lane and show through it)."""
    order = sorted(range(len(intervals)), key=lambda i: intervals[i])
    lane_ends: list[float] = []
    lanes = [0] * len(intervals)
    for i in order:
        start, end = intervals[i]
        lane = next((k for k, free_at in enumerate(lane_ends) if free_at <= start), None)
        if lane is None:
            if len(lane_ends) < MAX_LANES:
                lane_ends.append(end)
                lane = len(lane_ends) - 1
            else:
                lane = MAX_LANES - 1
        lane_ends[lane] = max(lane_ends[lane], end)
        lanes[i] = lane
    return lanes


def _draw_row(ax: Any, y: int, row: TypeRow, timeline: Timeline) -> None:
    import numpy as np
    from matplotlib.collections import PolyCollection
    from matplotlib.colors import to_rgba

    bar_color = COMPLEX_COLOR if row.complex else (row.color or INTERVAL_COLOR)
    tick_color = COMPLEX_COLOR if row.complex else (row.color or POINT_COLOR)
    if row.lags:
        # occurrence -> arrival: a thin line from the event's end time to when the store
        # received it, a dot at the arrival; shorter than a pixel column is not drawn
        late = [(e, a) for e, a in row.lags if a - e > timeline.bin_width]
        if late:
            ys = y + TICK_HALF * 0.75
            ax.hlines([ys] * len(late), [e for e, _ in late], [a for _, a in late],
                      colors=LAG_COLOR, linewidth=1.0, zorder=3)
            ax.plot([a for _, a in late], [ys] * len(late), linestyle="none", marker="o",
                    markersize=2.5, color=LAG_COLOR, zorder=3)
    if row.mode == "exact":
        if row.intervals:
            lanes = _lanes(row.intervals)
            n_lanes = max(lanes) + 1
            height = 2 * BAR_HALF / n_lanes
            bottoms = [y - BAR_HALF + lane * height for lane in lanes]
            # one PolyCollection per row whatever the number of intervals: one artist
            ax.add_collection(PolyCollection(
                [[(s, b), (s, b + height), (e, b + height), (e, b)]
                 for (s, e), b in zip(row.intervals, bottoms)],
                facecolors=bar_color, edgecolors="white", linewidths=0.5, alpha=0.8,
                hatch="///" if row.complex else None))
        if row.points:
            ax.vlines(row.points, y - TICK_HALF, y + TICK_HALF, colors=tick_color,
                      linewidth=1.4 if len(row.points) < 200 else 0.8)
        return
    # binned: one image strip for the interval coverage, one set of ticks for the points
    width = timeline.bin_width
    if row.coverage is not None and row.coverage.any():
        rgba = np.zeros((1, timeline.bins, 4))
        rgba[0, :, :3] = to_rgba(bar_color)[:3]
        rgba[0, :, 3] = _density_alpha(row.coverage)
        ax.imshow(rgba, extent=(timeline.start, timeline.end, y + BAR_HALF, y - BAR_HALF),
                  aspect="auto", interpolation="nearest", origin="upper", zorder=2)
    if row.point_counts is not None and row.point_counts.any():
        used = np.nonzero(row.point_counts)[0]
        colors = np.tile(to_rgba(tick_color), (len(used), 1))
        colors[:, 3] = _density_alpha(row.point_counts)[used]
        ax.vlines(timeline.start + (used + 0.5) * width, y - TICK_HALF, y + TICK_HALF,
                  colors=colors, linewidth=1.0)


def _draw_query(ax: Any, y: int, row: QueryRow) -> None:
    """A goal's answers over time: a bar per run of one answer, in that answer's color,
    labelled when the bar is wide enough; no bar where there was no answer."""
    from matplotlib.collections import PolyCollection

    shown = [(a, b, text) for a, b, text in row.runs if text is not None]
    if shown:
        ax.add_collection(PolyCollection(
            [[(a, y - BAR_HALF), (a, y + BAR_HALF), (b, y + BAR_HALF), (b, y - BAR_HALF)]
             for a, b, _ in shown],
            facecolors=[row.colors[text] for _, _, text in shown], edgecolors="white",
            linewidths=0.5, alpha=0.85))
    x0, x1 = ax.get_xlim()
    width_px = ax.get_window_extent().width or 1.0
    font_px = FONT_PT * ax.figure.dpi / 72.0
    for a, b, text in shown:
        bar_px = (b - a) / (x1 - x0) * width_px
        if bar_px > 0.62 * font_px * 0.85 * (len(text) + 1):
            ax.text((a + b) / 2, y, text, ha="center", va="center", color="white",
                    fontsize=FONT_PT * 0.85, clip_on=True)


def _draw_series(ax: Any, series: ValueSeries, timeline: Timeline) -> None:
    color = COMPLEX_COLOR if series.complex else VALUE_COLOR
    if series.lines:
        for key, key_color, times, values in series.lines:
            ax.plot(times, values, color=key_color, linewidth=1.3, label=key,
                    marker="o" if len(times) <= 200 else None, markersize=3)
        ax.legend(fontsize=FONT_PT * 0.8, frameon=False, loc="best")
    elif series.mode == "binned":
        ax.fill_between(series.times, series.lows, series.highs, color=color, alpha=0.25,
                        linewidth=0, step="mid")
        ax.plot(series.times, series.values, color=color, linewidth=1.0)
    elif series.times:
        ax.plot(series.times, series.values, color=color, linewidth=1.3,
                marker="o" if len(series.times) <= 200 else None, markersize=3)
    if not series.times:
        ax.text(0.5, 0.5, "no values in the window", transform=ax.transAxes, ha="center",
                va="center", color="#777777", fontsize=FONT_PT)
    label = (COMPLEX_MARK if series.complex else "") + series.spec.text
    ax.set_ylabel(label, fontsize=FONT_PT, rotation=0, ha="right", va="center",
                  color=color if series.complex else "black")
    ax.tick_params(labelsize=FONT_PT * 0.85)
    ax.grid(True, axis="y", color="#e6e6e6", linewidth=0.6)


def draw_timeline(timeline: Timeline) -> Any:
    """The matplotlib Figure of a :class:`Timeline` (Agg canvas; never a window).
    Epoch-second data (``timeline.origin`` set) is drawn on a relative axis: seconds since
    the origin, which the axis label names as a UTC time.

    >>> import slr_sql
    >>> kb = slr_sql.open(clock=slr_sql.ManualClock(0)); kb.add("move(r1)^[2, 8]"); kb.add("bump(r1)^5")
    >>> fig = draw_timeline(collect_timeline(kb, start=0, end=10))
    >>> [label.get_text() for label in fig.axes[0].get_yticklabels()]
    ['bump/1', 'move/1']
    """
    drawn = timeline
    if timeline.origin:
        timeline = _shifted(timeline, timeline.origin)
    fig = _draw(timeline)
    fig.slr_timeline = drawn  # what was drawn, for callers that want the numbers
    return fig


def _shifted(timeline: Timeline, origin: float) -> Timeline:
    """A copy of ``timeline`` with every time minus ``origin``."""
    import dataclasses

    rows = [dataclasses.replace(
        row, intervals=[(a - origin, b - origin) for a, b in row.intervals],
        points=[p - origin for p in row.points],
        lags=[(e - origin, a - origin) for e, a in row.lags]) for row in timeline.rows]
    series = [dataclasses.replace(
        s, times=[t - origin for t in s.times],
        lines=[(k, c, [t - origin for t in ts], vs) for k, c, ts, vs in s.lines])
        for s in timeline.series]
    queries = [dataclasses.replace(q, runs=[(a - origin, b - origin, text)
                                            for a, b, text in q.runs])
               for q in timeline.queries]
    return dataclasses.replace(timeline, start=timeline.start - origin,
                               end=timeline.end - origin, rows=rows, series=series,
                               queries=queries)


def _draw(timeline: Timeline) -> Any:
    Figure, FigureCanvasAgg = _matplotlib()
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    fig = Figure(figsize=(timeline.width / timeline.dpi, timeline.height / timeline.dpi),
                 dpi=timeline.dpi)
    FigureCanvasAgg(fig)
    n_rows = len(timeline.rows) + len(timeline.queries)
    n_series = len(timeline.series)
    ratios = [max(n_rows, 1) * 3.2] + [12.0] * n_series
    grid = fig.add_gridspec(1 + n_series, 1, height_ratios=ratios, left=timeline.left,
                            right=timeline.right, top=timeline.top, bottom=timeline.bottom,
                            hspace=0.12 if n_series else 0)
    ax = fig.add_subplot(grid[0])
    ax.set_xlim(timeline.start, timeline.end)
    ax.set_ylim(max(n_rows, 1) - 0.5, -0.5)
    ax.set_yticks(range(n_rows))
    ax.set_yticklabels([(COMPLEX_MARK if row.complex else "") + row.label
                        for row in timeline.rows] + [q.label for q in timeline.queries],
                       fontsize=FONT_PT)
    for label, row in zip(ax.get_yticklabels(), timeline.rows):
        if row.complex:
            label.set_color(COMPLEX_COLOR)
    ax.tick_params(axis="y", length=0)
    ax.tick_params(axis="x", labelsize=FONT_PT * 0.85)
    for y in range(n_rows - 1):
        ax.axhline(y + 0.5, color="#eeeeee", linewidth=0.6, zorder=0)
    for y, row in enumerate(timeline.rows):
        _draw_row(ax, y, row, timeline)
    for y, query_row in enumerate(timeline.queries, start=len(timeline.rows)):
        _draw_query(ax, y, query_row)
    if not n_rows:
        ax.text(0.5, 0.5, f"no events between {timeline.start:g} and {timeline.end:g}",
                transform=ax.transAxes, ha="center", va="center", color="#777777",
                fontsize=FONT_PT)
    axes = [ax]
    for series in timeline.series:
        value_ax = fig.add_subplot(grid[len(axes)], sharex=ax)
        _draw_series(value_ax, series, timeline)
        axes.append(value_ax)
    for upper in axes[:-1]:
        upper.tick_params(axis="x", labelbottom=False)
    if timeline.origin:
        import datetime

        try:
            since = datetime.datetime.fromtimestamp(timeline.origin, tz=datetime.UTC)
        except (OverflowError, ValueError, OSError):   # no calendar date: seconds only
            axes[-1].set_xlabel(f"time (s) since {timeline.origin:.0f}", fontsize=FONT_PT)
        else:
            axes[-1].set_xlabel(f"time (s) since {since:%Y-%m-%d %H:%M:%S} UTC "
                                f"({timeline.origin:.0f})", fontsize=FONT_PT)
    else:
        axes[-1].set_xlabel("time (s)", fontsize=FONT_PT)

    # The legend names what the picture shows, and nothing else.
    plain = [row for row in timeline.rows if not row.complex]
    handles = []
    if any(row.intervals or (row.coverage is not None and row.coverage.any()) for row in plain):
        handles.append(Patch(facecolor=INTERVAL_COLOR, alpha=0.8, label="interval"))
    if any(row.points or (row.point_counts is not None and row.point_counts.any())
           for row in plain):
        handles.append(Line2D([], [], color=POINT_COLOR, linewidth=1.4, label="point"))
    if any(row.complex and row.count for row in timeline.rows) or any(
            s.complex and s.count for s in timeline.series):
        handles.append(Patch(facecolor=COMPLEX_COLOR, alpha=0.8, hatch="///",
                             label=COMPLEX_MARK + "complex event"))
    if any(row.lags and any(a - e > timeline.bin_width for e, a in row.lags)
           for row in timeline.rows):
        handles.append(Line2D([], [], color=LAG_COLOR, linewidth=1.0, marker="o",
                              markersize=2.5, label="arrival lag"))
    if any(row.mode == "binned" for row in timeline.rows) or any(
            s.mode == "binned" for s in timeline.series):
        handles.append(Patch(facecolor="#bbbbbb",
                             label="binned: darker = more events per pixel column"))
    if handles:
        ax.legend(handles=handles, loc="lower right", bbox_to_anchor=(1.0, 1.0),
                  ncol=len(handles), fontsize=FONT_PT * 0.85, frameon=False, borderaxespad=0.2,
                  handlelength=1.4)
    if timeline.title:
        fig.suptitle(timeline.title, x=timeline.left, ha="left", fontsize=FONT_PT * 1.15,
                     y=1 - 0.6 * FONT_PT * timeline.dpi / 72 / timeline.height)
    return fig


def timeline(source: Any, types: Iterable[str] | str | None = None, *,
             start: float | None = None, end: float | None = None,
             values: Iterable[str] | str = (), complex_types: Iterable[str] | None = None,
             size: tuple[int, int | None] | None = None, dpi: int = DEFAULT_DPI,
             title: str | None = None, exact_limit: int | None = None,
             by: Iterable[str] | str = (), lags: bool | None = None, internal: bool = False,
             relative: bool | None = None, query: str | None = None,
             every: float | None = None, timeout: float | None = None) -> Any:
    """A timeline of the event histories in ``source`` as a matplotlib Figure.

    ``source`` is anything with ``sql(query, params)`` (a knowledge base or an EventStore).
    ``types``: event types to draw, each ``name`` (every arity) or ``name/arity``, one row each
    in that order; default every type with events in the window, by name. ``start``/``end``:
    the time window (default: the span of the events, plus 2 %). ``values``: numeric arguments
    drawn as lines, each ``TYPE:ARG`` (``speed:1``, ``seg:arg2[0]``, ``tf:3.pose[0][0]``).
    ``complex_types``: names of complex event types, marked in red with a diamond; None asks
    ``source.complex_event_types()`` when the source has it. ``size``: (width, height) in
    pixels, height None to fit the rows; ``dpi`` scales the text and lines. Types or value
    series with more events in the window than ``exact_limit`` (default: the number of pixel
    columns of the plot area) are aggregated per pixel column. ``by``: ``TYPE:ARG`` gives
    each value of that argument its own row and color (``seg:1``: a row per object), and a
    value line of that type a line per value (without it, a value line is split by the first
    argument when it names a few objects). ``lags``: draw each event's arrival lag, from its
    end time to its arrival (default: when the arrivals share the events' clock).
    ``internal``: also the store's own types (``slr_import/3``). ``relative``: a time axis
    relative to the window's start (default: for epoch-second data). ``query`` with
    ``every``: a row with the goal's answers over time, the goal asked with ``T`` bound to
    each sample time (``location(cup1, L)^T``); ``timeout``: seconds all those asks may take
    together (each is given the time left), else :class:`~slr_sql.errors.SLRTimeout`.

    >>> import slr_sql
    >>> kb = slr_sql.open(clock=slr_sql.ManualClock(0))
    >>> kb.add("speed(0.5)^1"); kb.add("speed(0.7)^2")
    >>> fig = timeline(kb, values=["speed:1"], size=(400, 300), dpi=50)
    >>> fig.get_size_inches().tolist(), len(fig.axes)
    ([8.0, 6.0], 2)
    >>> kb.close()
    """
    _matplotlib()  # say how to install matplotlib before reading anything
    return draw_timeline(collect_timeline(
        source, types, start=start, end=end, values=values, complex_types=complex_types,
        size=size, dpi=dpi, title=title, exact_limit=exact_limit, by=by, lags=lags,
        internal=internal, relative=relative, query=query, every=every, timeout=timeout))


IMAGE_FORMATS = {".png": "png", ".jpg": "jpg", ".jpeg": "jpg", ".svg": "svg", ".pdf": "pdf"}


def check_image_target(path: str, store: str | None = None) -> None:
    """Refuse (SLRError), before any work, to write an image over an SQLite database (the
    store being drawn reached through a link, another store) or over ``store``'s own files
    (it, its ``-wal``, ``-shm``, ``-journal``, whatever their spelling): matplotlib writes
    through a link and truncates what is there, and ``slr plot robot.db -o view.png`` with
    ``view.png`` a link to ``robot.db`` left an image where the store was.

    >>> import os, tempfile, slr_sql
    >>> folder = tempfile.mkdtemp(); db = os.path.join(folder, "robot.db")
    >>> slr_sql.open(db).close(); os.symlink(db, os.path.join(folder, "view.png"))
    >>> check_image_target(os.path.join(folder, "view.png"), db)
    Traceback (most recent call last):
        ...
    slr_sql.errors.SLRError: cannot write .../view.png: it is the store being drawn (.../robot.db): writing the image there would destroy the store
    """
    import os

    real = os.path.realpath(path)
    if store is not None and "://" not in store:
        for suffix in ("", "-wal", "-shm", "-journal"):
            if real == os.path.realpath(store) + suffix:
                what = "the store being drawn" if not suffix else \
                    "the name of a file SQLite keeps beside the store being drawn"
                raise SLRError(f"cannot write {path}: it is {what} ({store}{suffix}): "
                               "writing the image there would destroy the store")
    import stat

    try:
        if not stat.S_ISREG(os.stat(real).st_mode):
            return      # (a named pipe a viewer reads: its open would wait for a writer)
        with open(real, "rb") as existing:
            head = existing.read(16)
    except OSError:
        return          # (no such file: made; another reason: writing it says why)
    if head == b"SQLite format 3\x00":
        raise SLRError(f"cannot write {path}: it is an SQLite database (a store?), not an "
                       "image; remove the file first or choose another name")


def save_timeline(figure: Any, path: str) -> None:
    """Write a timeline figure at its own size and dpi (``slr plot -o``) in the format its
    suffix names: .png, .jpg/.jpeg, .svg or .pdf; any other suffix is refused.

    >>> import pathlib, tempfile, slr_sql
    >>> kb = slr_sql.open(clock=slr_sql.ManualClock(0)); kb.add("move(r1)^[2, 8]")
    >>> fig = draw_timeline(collect_timeline(kb, start=0, end=10))
    >>> path = pathlib.Path(tempfile.mkdtemp()) / "moves.svg"
    >>> save_timeline(fig, str(path)); path.read_text()[:5]
    '<?xml'
    >>> save_timeline(fig, "moves.gif")
    Traceback (most recent call last):
        ...
    slr_sql.errors.SLRError: cannot write moves.gif: the suffix .gif names no image format; use .png, .jpg, .jpeg, .svg, .pdf
    """
    import os

    suffix = os.path.splitext(str(path))[1].lower()
    fmt = IMAGE_FORMATS.get(suffix)
    if fmt is None:
        raise SLRError(f"cannot write {path}: the suffix {suffix or '(none)'} names no image "
                       f"format; use {', '.join(IMAGE_FORMATS)}")
    try:
        figure.savefig(path, dpi=figure.dpi, format=fmt)
    except OSError as exc:
        raise SLRError(f"cannot write {path}: {exc.strerror or exc}") from None
