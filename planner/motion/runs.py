"""The motion's pieces grouped into runs: the robot rests only between runs, where it must (a hand closes on the object
or lets go of it, the object is lifted off or set down, the object's situation changes), and at the task's ends.
Each run is timed and smoothed as one trajectory (smoothing.py)."""
from __future__ import annotations

import numpy as np

from planner.motion.piece import Piece

RESTS = ("closing", "opening")  # a hand closes on the object or lets go of it: the robot rests before and after


def starts_run(piece: Piece) -> bool:
    """Whether a run starts at the piece whatever comes before it: a hand closing or opening, or a lift."""
    return piece.part in RESTS or piece.part == "lift"


def ends_run(piece: Piece) -> bool:
    """Whether a run ends with the piece whatever comes after it: a hand closing or opening, or a set-down."""
    return piece.part in RESTS or piece.part == "set-down"


def runs(pieces: list[Piece]) -> list[list[Piece]]:
    """The pieces grouped into runs (see the module): a piece joins the run before it when neither closes a hand on
    the object nor lets go of it, the object is where it was (static at one pose, or held by one hand in one grasp)
    and it is neither set down nor lifted off between them."""
    out: list[list[Piece]] = []
    for piece in pieces:
        if out:
            last = out[-1][-1]
            if (not ends_run(last) and not starts_run(piece) and last.situation.holder == piece.situation.holder
                    and np.array_equal(last.situation.pose, piece.situation.pose)):
                out[-1].append(piece)
                continue
        out.append([piece])
    return out


def run_key(run: list[Piece]) -> tuple:
    """What identifies a run (its pieces' phases, parts and paths), also in another process."""
    return tuple((int(p.phase), p.part, p.path.tobytes()) for p in run)
