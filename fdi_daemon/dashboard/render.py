"""The dashboard view: a status snapshot (DESIGN/TEAM "Status snapshot") -> a rich renderable.

`render(snapshot, notice)` is pure: it reads the snapshot dict and nothing else. The returned
`DashboardView` picks its layout from the size rich gives it when drawn:

- standard (>= 80 x 24): header; left column with link health, monitor numbers, model and
  provenance; right column with θ1 and θ2 braille plots (band edges and signature level drawn
  in), the friction trend of the last hours with the alarm's state (when the snapshot has
  an ``alarm`` section: a daemon), and the alarm list;
- larger terminals get wider columns, taller plots, more alarm rows, link details and, from
  120 columns and about 40 rows, the θ2-vs-θ1 plane under the model panel;
- below 80 x 24 a compact view keeps the state, the numbers, small plots and the last alarms.

Missing keys, ``null`` band and NaN θ (while calibrating) are shown as "—", never an error.
"""

from __future__ import annotations

import math
import numbers
import time as _time
from collections.abc import Iterable
from typing import Any

from rich.console import Console, ConsoleOptions, Group, RenderResult
from rich.layout import Layout
from rich.panel import Panel
from rich.text import Text

from fdi_daemon.dashboard.plot import BraillePlot, Series, data_range, padded_range

#: state -> (label, badge style); unknown states are shown as they come, in white
STATE_BADGES: dict[str, tuple[str, str]] = {
    "starting": ("STARTING", "bold white on grey37"),
    "calibrating": ("CALIBRATING", "bold black on cyan"),
    "monitoring": ("MONITORING", "bold black on green"),
    "fault_detected": ("FAULT DETECTED", "bold black on yellow"),
    "friction_isolated": ("FRICTION ISOLATED", "bold white on red"),
    "other_fault": ("OTHER FAULT", "bold white on magenta"),
}

#: event kind -> style in the alarm list
EVENT_STYLES: dict[str, str] = {
    "fault_detected": "bold yellow",
    "friction_isolated": "bold red",
    "other_fault": "bold magenta",
    "cleared": "green",
    "calibrated": "cyan",
    "data_gap": "yellow",
    "bad_sample": "yellow",
    "link_lost": "red",
    "link_restored": "green",
    "alarm_raised": "bold red",
    "alarm_priority": "bold red",
    "alarm_acknowledged": "yellow",
    "alarm_shelved": "magenta",
    "alarm_unshelved": "magenta",
    "alarm_returned": "green",
}

THETA_NAMES = ("theta1", "theta2")
THETA_LABELS = ("θ1 Coulomb", "θ2 viscous")
TRACE_STYLE = "bold bright_cyan"
BAND_STYLE = "yellow"
SIGNATURE_STYLE = "magenta"
#: the signature level is drawn in only if showing it stretches the scale at most this much
SIGNATURE_ZOOM_LIMIT = 6.0
COMPACT_WIDTH, COMPACT_HEIGHT = 80, 24
#: the θ1-θ2 plane needs this many rows (inside its border) under a model panel of so many
PLANE_MIN_ROWS, MODEL_ROWS_WITH_PLANE = 10, 6
_EVENT_SHOWN_KEYS = ("t", "time", "kind", "theta1", "theta2")
#: what an event row shows right after its time and kind, before θ and the other fields
#: (field -> short label); what does not fit the row's width is left out from the end
EVENT_KEY_FIELDS: dict[str, tuple[tuple[str, str], ...]] = {
    "fault_detected": (("statistic", "stat"), ("path", "")),
    "friction_isolated": (("coulomb_change", "Δθ1"), ("friction_evidence", "")),
    "other_fault": (("coulomb_change", "Δθ1"), ("reason", "")),
    "calibrated": (("samples", "samples"),),
    "data_gap": (("missing_samples", "missing"),),
    "bad_sample": (("count", "count"), ("reason", "")),
    "alarm_raised": (("priority", "prio"), ("classification", "")),
    "alarm_priority": (("priority", "prio"), ("level", "level"), ("step", "step")),
    "alarm_acknowledged": (("by", "by"),),
    "alarm_returned": (("level", "level"),),
}
#: legend marks in the θ plot titles: the trace, the signature level, the band edges
TRACE_MARK, SIGNATURE_MARK, BAND_MARK = "━", "━", "╍"
#: the trend panel: level mean per bucket, its maximum, the baseline, the alarm steps
TREND_MEAN_STYLE, TREND_MAX_STYLE = TRACE_STYLE, "blue"
BASELINE_STYLE, STEP_STYLE = "green", "yellow"
#: alarm state (lifecycle.STATES, or shelved) -> (label, style) in the trend panel's border
ALARM_LABELS: dict[str, tuple[str, str]] = {
    "normal": ("no alarm", "green"),
    "unacknowledged": ("ALARM P{p} unacknowledged", "bold white on red"),
    "acknowledged": ("alarm P{p} acknowledged", "bold yellow"),
    "returned_unacknowledged": ("returned, unacknowledged", "bold yellow"),
}


def render(
    snapshot: dict[str, Any] | None, notice: str | None = None, footer: Text | None = None
) -> DashboardView:
    """The dashboard for one snapshot; `notice` (e.g. "daemon not reachable") tops the screen,
    `footer` (the keys, or a prompt) is its last line."""
    return DashboardView(snapshot, notice, footer)


class DashboardView:
    """A size-adaptive renderable of one snapshot."""

    def __init__(
        self,
        snapshot: dict[str, Any] | None,
        notice: str | None = None,
        footer: Text | None = None,
    ):
        self.snapshot = snapshot if isinstance(snapshot, dict) else {}
        self.notice = notice
        self.footer = footer

    def __rich_console__(self, console: Console, options: ConsoleOptions) -> RenderResult:
        width = options.max_width
        height = options.height or console.height
        yield self.layout(width, height)

    def layout(self, width: int, height: int) -> Layout:
        """The rich Layout for a screen of `width` x `height` cells."""
        if self.footer is not None and height > 2:
            layout = Layout()
            layout.split_column(
                Layout(DashboardView(self.snapshot, self.notice).layout(width, height - 1)),
                Layout(self.footer, name="footer", size=1),
            )
            return layout
        if width < COMPACT_WIDTH or height < COMPACT_HEIGHT:
            return _compact_layout(self.snapshot, self.notice, width, height)
        return _standard_layout(self.snapshot, self.notice, width, height)


# ---------------------------------------------------------------- small helpers


def number(value: Any) -> float:
    """`value` as a float (numpy scalars too); NaN for None, strings and anything else that
    is not a real number."""
    if type(value) is float:
        return value
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        return math.nan
    return float(value)


def fmt(value: Any, spec: str = "+.4g") -> str:
    """A number formatted by `spec`, or "—" when it is missing or not finite."""
    x = number(value)
    return "—" if not math.isfinite(x) else format(x, spec)


def fmt_count(value: Any) -> str:
    x = number(value)
    return "—" if not math.isfinite(x) else str(int(x))


def fmt_duration_us(value: Any) -> str:
    """A duration given in µs, in µs, ms or s, whichever reads best."""
    x = number(value)
    if not math.isfinite(x):
        return "—"
    if abs(x) < 1e3:
        return f"{x:.0f} µs"
    if abs(x) < 1e6:
        return f"{x / 1e3:.3g} ms"
    return f"{x / 1e6:.3g} s"


def state_badge(state: Any) -> Text:
    label, style = STATE_BADGES.get(str(state), (str(state or "unknown").upper(), "bold white"))
    return Text(f" {label} ", style=style)


def _section(snapshot: dict[str, Any], key: str) -> dict[str, Any]:
    value = snapshot.get(key)
    return value if isinstance(value, dict) else {}


def _band(monitor: dict[str, Any], index: int) -> tuple[float, float] | None:
    band = monitor.get("band")
    if not isinstance(band, dict):
        return None
    edges = band.get(THETA_NAMES[index])
    if not isinstance(edges, (list, tuple)) or len(edges) != 2:
        return None
    lo, hi = number(edges[0]), number(edges[1])
    return (lo, hi) if math.isfinite(lo) and math.isfinite(hi) else None


def _signature(monitor: dict[str, Any], index: int) -> float:
    signature = monitor.get("signature")
    if isinstance(signature, (list, tuple)) and len(signature) > index:
        return number(signature[index])
    return math.nan


def _history(monitor: dict[str, Any], index: int) -> tuple[list[float], list[float]]:
    history = monitor.get("history")
    if not isinstance(history, dict):
        return [], []
    t, y = _sequence(history.get("t")), _sequence(history.get(THETA_NAMES[index]))
    n = min(len(t), len(y))
    return [number(v) for v in t[:n]], [number(v) for v in y[:n]]


def _sequence(value: Any) -> list[Any]:
    """A list of the items of a list, tuple, deque or 1-D array; [] for anything else."""
    if value is None or isinstance(value, (str, bytes, dict)):
        return []
    try:
        return list(value)
    except TypeError:
        return []


def _line(*parts: tuple[str, str | None]) -> Text:
    text = Text(no_wrap=True, overflow="ellipsis")
    for content, style in parts:
        text.append(content, style=style)
    return text


def _kv(label: str, value: str, width: int, style: str | None = None) -> Text:
    """`label` left, `value` right-aligned in `width` cells."""
    gap = max(width - len(label) - len(value), 1)
    return _line((label, "dim"), (" " * gap, None), (value, style))


def _counter_style(value: Any) -> str | None:
    return "bold yellow" if number(value) > 0 else None


def _clock(unix_s: Any) -> str:
    x = number(unix_s)
    if not math.isfinite(x):
        return "—"
    return _time.strftime("%H:%M:%S", _time.localtime(x))


# ---------------------------------------------------------------- sections


def header(snapshot: dict[str, Any], notice: str | None, width: int) -> Group:
    """The notice line (if any) above one line with the state badge, sample time, link
    summary, event count and wall clock."""
    text = Text(no_wrap=True, overflow="ellipsis")
    text.append(" fdi ", style="bold reverse")
    text.append(" ")
    if snapshot:
        text.append_text(state_badge(snapshot.get("state")))
        if notice:
            text.append(" last known", style="dim")
        text.append(f"  t {fmt(snapshot.get('t'), '.2f')} s", style="bold")
        link = _section(snapshot, "link")
        if link:
            up = bool(link.get("connected"))
            text.append(f"  {link.get('kind', '?')} ", style="dim")
            text.append("●" if up else "○", style="green" if up else "red")
            text.append(f" {fmt(link.get('rate_hz'), '.1f')} Hz")
        alarms = snapshot.get("alarms") or []
        if width >= 100:
            text.append(f"  {len(alarms)} events", style="dim")
        if width >= 90 and not notice:
            text.append(f"  {_clock(snapshot.get('time'))}", style="dim")
    elif not notice:
        text.append("waiting for the first snapshot", style="dim")
    if not notice:
        return Group(text)
    banner = Text(f" {notice}", style="bold white on red", no_wrap=True, overflow="ellipsis")
    banner.pad_right(max(width - len(banner), 0))
    return Group(banner, text)


def header_size(notice: str | None) -> int:
    return 2 if notice else 1


def link_lines(link: dict[str, Any], width: int, detail: bool = False) -> list[Text]:
    """Link health: kind and connection, rate, samples, gaps/CRC errors/bad samples, tick
    latency p50/p99, deadline misses; with `detail` also the address, duplicates, missing
    samples and lateness when the snapshot has them."""
    if not link:
        return [Text("no link information", style="dim")]
    up = bool(link.get("connected"))
    latency = _section(link, "tick_latency_us")
    lines = [
        _kv(
            str(link.get("kind", "?")),
            "● up" if up else "○ DOWN",
            width,
            "bold green" if up else "bold red",
        ),
        _kv("rate", f"{fmt(link.get('rate_hz'), '.1f')} Hz", width),
        _kv(
            "samples",
            fmt_count(link.get("samples"))
            + (f"/{fmt_count(link['total_samples'])}" if "total_samples" in link else ""),
            width,
        ),
        _counters_line(link, (("gaps", "gaps"), ("CRC", "crc_errors"), ("bad", "bad_samples"))),
        _kv(
            "tick p50/99",
            f"{fmt_duration_us(latency.get('p50'))}/{fmt_duration_us(latency.get('p99'))}",
            width,
        ),
        _kv(
            "deadline miss",
            fmt_count(link.get("deadline_misses")),
            width,
            _counter_style(link.get("deadline_misses")),
        ),
    ]
    if detail:
        if "where" in link:
            lines.insert(1, _line((str(link["where"]), "dim")))
        if "duplicates" in link or "missing_samples" in link:
            lines.append(
                _counters_line(link, (("duplicates", "duplicates"), ("missing", "missing_samples")))
            )
        lateness = _section(link, "lateness_us")
        if lateness:
            lines.append(_kv("lateness p99", fmt_duration_us(lateness.get("p99")), width))
    return lines


def _counters_line(link: dict[str, Any], names: tuple[tuple[str, str], ...]) -> Text:
    """Several counters on one line, non-zero ones highlighted."""
    parts: list[tuple[str, str | None]] = []
    for label, key in names:
        parts += [
            (f"{label} ", "dim"),
            (fmt_count(link.get(key)), _counter_style(link.get(key))),
            ("  ", None),
        ]
    return _line(*parts[:-1])


def monitor_lines(monitor: dict[str, Any], width: int) -> list[Text]:
    """θ1, θ2, friction level, residual RMS, test statistic against its threshold."""
    if not monitor:
        return [Text("no monitor yet", style="dim")]
    statistic, threshold = number(monitor.get("statistic")), number(monitor.get("threshold"))
    over = math.isfinite(statistic) and math.isfinite(threshold) and statistic > threshold
    signature = monitor.get("signature")
    sig_text = "—"
    if isinstance(signature, (list, tuple)) and len(signature) == 2:
        sig_text = f"({fmt(signature[0], '.3g')}, {fmt(signature[1], '.3g')})"
    return [
        _kv("θ1 Coulomb", fmt(monitor.get("theta1")), width, "bold"),
        _kv("θ2 viscous", fmt(monitor.get("theta2")), width, "bold"),
        _kv("signature", sig_text, width, SIGNATURE_STYLE),
        _kv("friction level", fmt(monitor.get("friction_level"), ".3g"), width),
        _kv("residual RMS", fmt(monitor.get("residual_rms"), ".3e"), width),
        _kv(
            "stat/thr",
            f"{fmt(statistic, '.3g')}/{fmt(threshold, '.3g')}",
            width,
            "bold red" if over else None,
        ),
    ]


def flatten(mapping: dict[str, Any], prefix: str = "") -> Iterable[tuple[str, Any]]:
    """Nested provenance as (dotted.key, value) pairs, in the mapping's order."""
    for key, value in mapping.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            yield from flatten(value, name + ".")
        else:
            yield name, value


def shorten_path(path: str, width: int) -> str:
    """`path` cut from the left to `width` cells, keeping the file name."""
    return path if len(path) <= width else "…" + path[-(width - 1) :]


def _plain_value(value: Any) -> str:
    if isinstance(value, float):
        return format(value, ".4g")
    if isinstance(value, list):
        return ", ".join(_plain_value(v) for v in value)
    return str(value)


def _section_summary(section: dict[str, Any], room: int = 10**6) -> str:
    """One line from the well-known leaves of a provenance section (γ_f, fit, date, source),
    as many of them as fit in `room` cells (whole parts only)."""
    leaves: dict[str, Any] = {}
    for path, value in flatten(section):
        if path.count(".") <= 1:
            leaves.setdefault(path.rsplit(".", 1)[-1], value)
    parts = []
    if isinstance(leaves.get("gamma_f"), (int, float)):
        gamma = f"γ_f {leaves['gamma_f']:.3g}"
        flat = " (flat cost)" if len(gamma) + 12 <= room else " (flat)"
        parts.append(gamma + (flat if leaves.get("flat") is True else ""))
    if isinstance(leaves.get("fit_percent"), (int, float)):
        parts.append(f"fit {leaves['fit_percent']:.1f} %")
    date = leaves.get("date_utc", leaves.get("date"))
    if isinstance(date, str):
        parts.append(date[:10])
    if isinstance(leaves.get("source"), str):
        parts.append(leaves["source"].rsplit("/", 1)[-1])
    while len(parts) > 1 and len(", ".join(parts)) > room:
        parts.pop()
    return ", ".join(parts)


def _is_path_or_hash(entry: tuple[str, str]) -> bool:
    """File paths, commands and checksums: what a narrow panel can spare first."""
    key, value = entry
    return "/" in value or key.endswith(("sha256", "command"))


def model_lines(model: dict[str, Any], width: int, rows: int) -> list[Text]:
    """The model path (one row, cut from the left); then provenance: top-level values, a
    one-line summary per section (identify, signature, ...), and as many of the remaining
    entries as `rows` allows, file paths and commands last."""
    if not model:
        return [Text("no model information", style="dim")]
    lines = [_line((shorten_path(str(model.get("path", "—")), width), "bold"))]
    provenance = model.get("provenance")
    if not isinstance(provenance, dict):
        return lines
    entries: list[tuple[str, str]] = []
    summaries: list[tuple[str, str]] = []
    for key, value in provenance.items():
        summary = (
            _section_summary(value, width - len(str(key)) - 2) if isinstance(value, dict) else ""
        )
        if summary:
            summaries.append((str(key), summary))
        else:
            entries += [(path, _plain_value(v)) for path, v in flatten({key: value})]
    details = [
        (path, _plain_value(v))
        for key, _ in summaries
        for path, v in flatten({key: provenance[key]})
    ]
    entries = (
        [entry for entry in entries if "." not in entry[0]]
        + summaries
        + sorted([entry for entry in entries if "." in entry[0]] + details, key=_is_path_or_hash)
    )
    room = max(rows - 1, 0)
    shown = entries if len(entries) <= room else entries[: max(room - 1, 0)]
    for key, value in shown:
        lines.append(_line((f"{key}: ", "dim"), (value, None)))
    if len(shown) < len(entries) and room:
        lines.append(Text(f"… {len(entries) - len(shown)} more", style="dim"))
    return lines


def _field_text(label: str, value: Any) -> str:
    spec = "+.3g" if label.startswith("Δ") else ".3g"  # a change carries its sign
    shown = format(value, spec) if isinstance(value, float) else str(value)
    return f"{label} {shown}" if label else shown


def alarm_lines(alarms: list[Any], width: int, rows: int) -> list[Text]:
    """Newest first: sample time, wall clock (when there is room), kind, the kind's key
    fields (`EVENT_KEY_FIELDS`), θ, then the other fields, as many as fit in `width`."""
    events = [a for a in alarms if isinstance(a, dict)]
    if not events:
        return [Text("no events", style="dim")]
    shown = list(reversed(events))[:rows]
    times = [f"{fmt(event.get('t'), '.3f')} s" for event in shown]
    time_width = max(len(t) for t in times)
    kind_width = max(len(str(event.get("kind", "?"))) for event in shown)
    lines = []
    for event, t_text in zip(shown, times):
        kind = str(event.get("kind", "?"))
        text = Text(no_wrap=True, overflow="ellipsis")
        text.append(f"{t_text:>{time_width}} ", style="bold")
        if width >= 64 and "time" in event:
            text.append(f"{_clock(event.get('time'))} ", style="dim")
        text.append(f"{kind:<{kind_width}}", style=EVENT_STYLES.get(kind, "white"))
        key_fields = EVENT_KEY_FIELDS.get(kind, ())
        parts: list[tuple[str, str | None]] = []
        for key, label in key_fields:
            if event.get(key) is not None:
                value = event[key]
                if key == "statistic" and "threshold" in event:
                    value = f"{fmt(value, '.3g')}/{fmt(event['threshold'], 'g')}"
                parts.append((_field_text(label, value), None))
        if "theta1" in event or "theta2" in event:
            parts.append(
                (f"θ {fmt(event.get('theta1'), '+.3g')} {fmt(event.get('theta2'), '+.3g')}", None)
            )
        skip = {*_EVENT_SHOWN_KEYS, *(key for key, _ in key_fields)}
        if kind == "fault_detected":
            skip.add("threshold")
        parts += [
            (f"{k}={format(v, '.4g') if isinstance(v, float) else v}", "dim")
            for k, v in event.items()
            if k not in skip and not isinstance(v, dict)
        ]
        for i, (content, style) in enumerate(parts):  # whole fields only, never cut
            gap = "  " if i == 0 else " "
            if len(text) + len(gap) + len(content) > width:
                break
            text.append(gap + content, style=style)
        lines.append(text)
    return lines


def _theta_layers(monitor: dict[str, Any], index: int) -> tuple[Series, list[Series], str]:
    """The trace, the band edges (dashed) and where the signature level is relative to the
    plotted range: "drawn" (then it is a layer too), "above", "below" or "" (no signature)."""
    t, y = _history(monitor, index)
    trace = Series(style=TRACE_STYLE, t=t, y=y)
    band = _band(monitor, index)
    layers = [Series(style=BAND_STYLE, level=v, dashed=True) for v in band] if band else []
    signature = _signature(monitor, index)
    if not math.isfinite(signature):
        return trace, layers, ""
    base = data_range([trace] + layers)
    if base is None or (
        max(base[1], signature) - min(base[0], signature)
        <= SIGNATURE_ZOOM_LIMIT * max(base[1] - base[0], 1e-12)
    ):
        return trace, layers + [Series(style=SIGNATURE_STYLE, level=signature)], "drawn"
    return trace, layers, "above" if signature > base[1] else "below"


def theta_plot(monitor: dict[str, Any], trace: Series, layers: list[Series]) -> BraillePlot:
    """A θ history (`trace`, drawn on top) over its band edges and signature level."""
    state = str(monitor.get("state", ""))
    empty = "calibrating…" if state == "calibrating" else "no data yet"
    if data_range([trace]) is None:
        return BraillePlot(series=[], empty_text=empty)
    layers.append(trace)
    y_data = data_range(layers)
    assert y_data is not None  # the trace has data
    return BraillePlot(series=layers, y_range=padded_range(*y_data), empty_text=empty)


def theta_title(monitor: dict[str, Any], index: int, width: int, where: str) -> Text:
    """ "━ θ1 Coulomb +0.98 ━ sig 1 ╍ band [lo, hi]", each part in the colour of what it
    names in the plot, so the title is the legend; the name shortens on narrow plots and an
    arrow marks a signature level outside the plotted range (`where` from `_theta_layers`)."""
    label = THETA_LABELS[index] if width >= 100 else THETA_LABELS[index].split()[0]
    title = Text()
    title.append(f"{TRACE_MARK} {label} {fmt(monitor.get(THETA_NAMES[index]))}", style=TRACE_STYLE)
    if where:
        arrow = {"above": "↑", "below": "↓"}.get(where, "")
        title.append(
            f" {SIGNATURE_MARK} sig {fmt(_signature(monitor, index), '.3g')}{arrow}",
            style=SIGNATURE_STYLE,
        )
    band = _band(monitor, index)
    if band is not None:
        title.append(
            f" {BAND_MARK} band [{fmt(band[0], '.3g')}, {fmt(band[1], '.3g')}]", style=BAND_STYLE
        )
    else:
        title.append(f" {BAND_MARK} band —", style=BAND_STYLE)
    return title


def theta_plane(monitor: dict[str, Any]) -> tuple[BraillePlot, str]:
    """θ2 against θ1 over the history: the band as a rectangle, the signature direction as a
    line from the origin to (1, γ_f), the trajectory, and the latest point on top. Returns
    the plot and a caption with the θ1 range (the horizontal axis)."""
    _, theta1 = _history(monitor, 0)
    _, theta2 = _history(monitor, 1)
    layers = []
    band1, band2 = _band(monitor, 0), _band(monitor, 1)
    if band1 and band2:
        layers.append(
            Series(
                style=BAND_STYLE,
                t=[band1[0], band1[1], band1[1], band1[0], band1[0]],
                y=[band2[0], band2[0], band2[1], band2[1], band2[0]],
            )
        )
    signature = (_signature(monitor, 0), _signature(monitor, 1))
    if all(math.isfinite(v) for v in signature):
        layers.append(Series(style=SIGNATURE_STYLE, t=[0.0, signature[0]], y=[0.0, signature[1]]))
    trace = Series(style=TRACE_STYLE, t=theta1, y=theta2)
    finite = [(x, y) for x, y in zip(theta1, theta2) if math.isfinite(x) and math.isfinite(y)]
    if not finite:
        return BraillePlot(series=[], empty_text="no θ yet"), ""
    latest = Series(style="bold white", t=[finite[-1][0]], y=[finite[-1][1]])
    layers += [trace, latest]
    xs = [x for s in layers for x in s.t if math.isfinite(x)]
    x_range = padded_range(min(xs), max(xs))
    y_data = data_range(layers)
    assert y_data is not None  # the latest point is finite
    plot = BraillePlot(series=layers, y_range=padded_range(*y_data), x_range=x_range)
    return plot, f"θ1 {x_range[0]:.3g} … {x_range[1]:.3g}"


def time_span_caption(monitor: dict[str, Any]) -> str:
    t, _ = _history(monitor, 0)
    finite = [v for v in t if math.isfinite(v)]
    if len(finite) < 2:
        return ""
    return f"t {finite[0]:.1f} … {finite[-1]:.1f} s"


def _trend_layers(alarm: dict[str, Any]) -> tuple[list[Series], tuple[float, float] | None]:
    """The trend's max and mean per bucket against hours before now, the baseline and the
    alarm steps (baseline + step) up to the first one above the data; and the y range."""
    trend = _section(alarm, "trend")
    means, highs = _sequence(trend.get("mean")), _sequence(trend.get("max"))
    bucket_h = number(trend.get("bucket_s")) / 3600
    if not means or not math.isfinite(bucket_h) or bucket_h <= 0:
        return [], None
    n = len(means)
    # each bucket a step from its start to its end (hours before now), so that one bucket
    # alone is a short line, not a dot; a bucket without data (NaN) breaks the line
    hours = [(i + k - n) * bucket_h for i in range(n) for k in (0, 1)]
    mean = Series(style=TREND_MEAN_STYLE, t=hours, y=[number(v) for v in means for _ in "ab"])
    high = Series(
        style=TREND_MAX_STYLE,
        t=hours,
        y=[number(v) for v in (highs + [None] * n)[:n] for _ in "ab"],
    )
    data = data_range([mean, high])
    if data is None:
        return [], None
    baseline = number(alarm.get("baseline_level"))
    base = baseline if math.isfinite(baseline) else 0.0
    layers = [Series(style=BASELINE_STYLE, level=baseline)] if math.isfinite(baseline) else []
    for step in sorted(number(v) for v in _sequence(alarm.get("steps"))):
        if math.isfinite(step):
            layers.append(Series(style=STEP_STYLE, level=base + step, dashed=True))
            if base + step > data[1]:
                break  # the next step to cross; higher ones would squash the trace
    layers += [high, mean]
    y_data = data_range(layers)
    assert y_data is not None  # mean and high have data
    return layers, padded_range(*y_data)


def trend_title(alarm: dict[str, Any]) -> Text:
    """ "━ level ━ max ━ base 0.08 ╍ steps +0.25/0.5/1", each part in its colour."""
    title = Text()
    title.append(f"{TRACE_MARK} level", style=TREND_MEAN_STYLE)
    title.append(f" {TRACE_MARK} max", style=TREND_MAX_STYLE)
    title.append(
        f" {TRACE_MARK} base {fmt(alarm.get('baseline_level'), '.3g')}", style=BASELINE_STYLE
    )
    steps = "/".join(fmt(v, ".3g") for v in _sequence(alarm.get("steps")))
    if steps:
        title.append(f" {BAND_MARK} steps +{steps}", style=STEP_STYLE)
    return title


def alarm_status(alarm: dict[str, Any]) -> Text:
    """The alarm's state, priority and shelving, for the trend panel's lower border."""
    until = number(alarm.get("shelved_until"))
    if alarm.get("state_code") == 4 and math.isfinite(until):
        return Text(f" shelved until {_clock(until)[:5]} ", style="bold magenta")
    state = str(alarm.get("state", "normal"))
    label, style = ALARM_LABELS.get(state, (state, "bold white"))
    return Text(f" {label.format(p=fmt_count(alarm.get('priority')))} ", style=style)


def trend_panel(alarm: dict[str, Any]) -> Panel:
    """The friction level of the last hours (the snapshot's ``alarm.trend``: mean and max per
    bucket) against the baseline and the alarm steps; the alarm's state in the border."""
    layers, y_range = _trend_layers(alarm)
    trend = _section(alarm, "trend")
    hours = len(_sequence(trend.get("mean"))) * number(trend.get("bucket_s")) / 3600
    span = f"-{hours:.3g} h … now " if layers else ""
    plot = BraillePlot(
        series=layers,
        y_range=y_range,
        x_range=(-hours, 0.0) if layers else None,
        empty_text="no trend yet",
    )
    subtitle = Text(span, style="dim")
    subtitle.append_text(alarm_status(alarm))
    return Panel(
        plot,
        title=trend_title(alarm),
        title_align="left",
        border_style="cyan",
        subtitle=subtitle,
        subtitle_align="right",
        padding=(0, 0),
    )


# ---------------------------------------------------------------- layouts


def _panel(
    body,
    title: str | Text,
    border: str = "blue",
    subtitle: str | None = None,
    padding: tuple[int, int] = (0, 1),
) -> Panel:
    return Panel(
        body,
        title=title,
        title_align="left",
        border_style=border,
        subtitle=subtitle or None,
        subtitle_align="right",
        padding=padding,
    )


def _plot_panel(monitor: dict[str, Any], index: int, width: int) -> Panel:
    trace, layers, where = _theta_layers(monitor, index)
    return _panel(
        theta_plot(monitor, trace, layers),
        theta_title(monitor, index, width, where),
        border="cyan",
        subtitle=time_span_caption(monitor) if index == 1 else None,
        padding=(0, 0),
    )


def _standard_layout(
    snapshot: dict[str, Any], notice: str | None, width: int, height: int
) -> Layout:
    link, monitor, model = (_section(snapshot, k) for k in ("link", "monitor", "model"))
    alarms = _sequence(snapshot.get("alarms"))
    left_width = max(30, min(60, width // 4))
    inner = left_width - 4
    body_height = height - header_size(notice)
    detail = height >= 32
    link_size, monitor_size = 2 + len(link_lines(link, inner, detail)), 8
    model_rows = max(body_height - link_size - monitor_size - 2, 1)
    model_size = None  # the model panel takes the rest of the column ...
    if width >= 120 and model_rows >= PLANE_MIN_ROWS + 2 + MODEL_ROWS_WITH_PLANE:
        model_rows = min(len(model_lines(model, inner, model_rows)), MODEL_ROWS_WITH_PLANE)
        model_size = model_rows + 2  # ... unless there is room for the θ plane below it
    alarm = snapshot.get("alarm")
    trend_size = (5 if body_height < 40 else 8) if isinstance(alarm, dict) else 0
    least = 4 if trend_size else 5  # the trend takes one event row from the smallest list
    alarm_rows = min(
        max(least, (body_height - 2) // 3 - (trend_size > 0)), 20, max(len(alarms), least)
    )
    layout = Layout()
    layout.split_column(
        Layout(header(snapshot, notice, width), name="header", size=header_size(notice)),
        Layout(name="body"),
    )
    layout["body"].split_row(Layout(name="left", size=left_width), Layout(name="right"))
    layout["left"].split_column(
        Layout(
            _panel(Group(*link_lines(link, inner, detail)), "link"), name="link", size=link_size
        ),
        Layout(
            _panel(Group(*monitor_lines(monitor, inner)), "monitor"),
            name="monitor",
            size=monitor_size,
        ),
        Layout(
            _panel(Group(*model_lines(model, inner, model_rows)), "model"),
            name="model",
            size=model_size,
        ),
    )
    if model_size is not None:
        plane, caption = theta_plane(monitor)
        layout["left"].add_split(
            Layout(
                _panel(plane, "θ2 vs θ1", border="cyan", subtitle=caption, padding=(0, 0)),
                name="plane",
            )
        )
    right_width = width - left_width
    alarm_title = f"alarms & events ({len(alarms)})"
    if notice and not snapshot:
        plots = Layout(
            Panel(Text(notice, style="bold red", justify="center"), border_style="red"),
            name="plots",
        )
    else:
        plots = Layout(name="plots")
        plots.split_column(
            Layout(_plot_panel(monitor, 0, right_width), name="theta1"),
            Layout(_plot_panel(monitor, 1, right_width), name="theta2"),
        )
    layout["right"].split_column(plots)
    if trend_size:
        assert isinstance(alarm, dict)  # trend_size is 0 otherwise
        layout["right"].add_split(Layout(trend_panel(alarm), name="trend", size=trend_size))
    layout["right"].add_split(
        Layout(
            _panel(Group(*alarm_lines(alarms, right_width - 4, alarm_rows)), alarm_title),
            name="alarms",
            size=alarm_rows + 2,
        )
    )
    return layout


def _compact_layout(
    snapshot: dict[str, Any], notice: str | None, width: int, height: int
) -> Layout:
    """Small terminals: header, three summary lines, small plots if they fit, last alarms."""
    link, monitor = _section(snapshot, "link"), _section(snapshot, "monitor")
    alarms = _sequence(snapshot.get("alarms"))
    latency = _section(link, "tick_latency_us")
    summary = [
        _line(
            ("θ1 ", "dim"),
            (fmt(monitor.get("theta1")), "bold"),
            ("  θ2 ", "dim"),
            (fmt(monitor.get("theta2")), "bold"),
            ("  rms ", "dim"),
            (fmt(monitor.get("residual_rms"), ".2e"), None),
        ),
        _line(
            ("link ", "dim"),
            (str(link.get("kind", "—")), None),
            (
                " up" if link.get("connected") else " DOWN",
                "green" if link.get("connected") else "red",
            ),
            (
                f" {fmt(link.get('rate_hz'), '.1f')} Hz gaps {fmt_count(link.get('gaps'))}"
                f" crc {fmt_count(link.get('crc_errors'))} bad {fmt_count(link.get('bad_samples'))}"
                f" p99 {fmt_duration_us(latency.get('p99'))}"
                f" miss {fmt_count(link.get('deadline_misses'))}",
                None,
            ),
        ),
    ]
    alarm = snapshot.get("alarm")
    if isinstance(alarm, dict):  # the alarm an operator handles, no room for its trend
        summary.append(_line(("alarm", "dim")).append_text(alarm_status(alarm)))
    alarm_rows = 2 if height >= 12 else 1
    layout = Layout()
    parts = [
        Layout(header(snapshot, notice, width), name="header", size=header_size(notice)),
        Layout(Group(*summary), name="summary", size=len(summary)),
    ]
    plot_height = height - header_size(notice) - len(summary) - alarm_rows
    if plot_height >= 4:
        plots = Layout(name="plots")
        plots.split_row(
            Layout(_plot_panel(monitor, 0, width // 2), name="theta1"),
            Layout(_plot_panel(monitor, 1, width // 2), name="theta2"),
        )
        parts.append(plots)
    parts.append(
        Layout(Group(*alarm_lines(alarms, width, alarm_rows)), name="alarms", size=alarm_rows)
    )
    layout.split_column(*parts)
    return layout
