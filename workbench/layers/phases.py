"""A motion's phases drawn: one colour per phase (by its index, cycling when a motion has more phases than colours),
routes coloured by phase, the phases' spans in time and the strip of coloured bands under the timeline."""
from __future__ import annotations

import numpy as np

from planner.core.plain_text import plain
from planner.motion.result import Motion

# Grasp, Carry, Place, Rest, then a table handover's Set down and Regrasp (planner/motion/phase.py); more phases cycle
PHASE_COLORS = ((0, 170, 170), (90, 60, 220), (200, 50, 200), (110, 110, 110), (230, 140, 20), (40, 160, 60))
PHASE_COLOR_NAMES = ("teal", "violet", "magenta", "grey", "orange", "green")


def phase_color(k: int) -> tuple[int, int, int]:
    """The colour of phase k (any k >= 0; the colours repeat after the sixth)."""
    return PHASE_COLORS[k % len(PHASE_COLORS)]


def phase_segments(points: np.ndarray, phase: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Line segments between consecutive samples of each track in `points` ((n, tracks, 3)), as ((n-1)*tracks, 2, 3)
    float32, and their colours by the phase of each segment's end sample (same shape, uint8)."""
    if len(points) < 2:
        return np.zeros((0, 2, 3), np.float32), np.zeros((0, 2, 3), np.uint8)
    ends = np.stack([points[:-1], points[1:]], axis=2)  # (n-1, tracks, 2 ends, 3)
    palette = np.asarray(PHASE_COLORS, np.uint8)
    colors = palette[np.asarray(phase[1:], int) % len(PHASE_COLORS)]  # (n-1, 3)
    colors = np.broadcast_to(colors[:, None, None, :], ends.shape)
    return ends.reshape(-1, 2, 3).astype(np.float32), np.ascontiguousarray(colors.reshape(-1, 2, 3))


def phase_spans(result: Motion) -> list[tuple[int, float, float]]:
    """(phase index, start s, end s) of each run of samples in one phase, in time order."""
    if not len(result.t):
        return []
    phase = np.asarray(result.phase, int)
    starts = np.flatnonzero(np.r_[True, phase[1:] != phase[:-1]])
    ends = np.r_[starts[1:], len(phase)]
    t = np.asarray(result.t, float)
    return [(int(phase[a]), float(t[a]), float(t[b] if b < len(t) else t[-1])) for a, b in zip(starts, ends)]


def phase_bands(result: Motion) -> str:
    """The phases as one strip of coloured bands, each as wide as its share of the motion's time and named (HTML, the
    names escaped), for the markdown under the timeline."""
    spans, total = phase_spans(result), max(float(result.duration), 1e-9)
    cells = []
    for k, start, end in spans:
        r, g, b = phase_color(k)
        name = plain(result.phase_name(k))
        width = max(100.0 * (end - start) / total, 0.5)
        cells.append(f"<span title='{name} {start:.2f}&#8211;{end:.2f} s' style='flex:0 0 {width:.2f}%;background:rgb({r},{g},{b});"
                     f"color:white;font-size:0.7em;overflow:hidden;white-space:nowrap;text-align:center'>{name}</span>")
    return f"<div style='display:flex;width:100%;border-radius:3px;overflow:hidden'>{''.join(cells)}</div>"
