"""Pairing two frame streams by presentation time, not by index (docs/method.md "Video").

Each frame of the *tick* stream (the left/first input by default) is one output frame; it is paired
with the frame of the *other* stream whose time is nearest. Two cameras rarely start together or
run at the same rate, so counting frames would drift; times do not. The other stream's frames that
no tick chose are *dropped*; a frame chosen by two consecutive ticks is *repeated*.

Times are in seconds on one shared clock (the second input already shifted by the user's offset).
Use exact numbers (``fractions.Fraction`` from ``pts * time_base``) where ties matter: a tick exactly
halfway between two other frames takes the earlier one, the frame still on screen at that instant.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from numbers import Real
from typing import Callable, Iterable, Iterator, Sequence, TypeVar

T = TypeVar("T")
U = TypeVar("U")


@dataclass
class PairingStats:
    """Counts of what pairing did, filled in while :func:`pair_by_time` runs.

    ``pairs``: ticks paired (= output frames). ``repeated``: ticks that reused the previous tick's
    other frame. ``dropped``: other frames passed over between the first and the last pair.
    ``unpaired_ticks_start`` / ``unpaired_other_start``: frames before both inputs are running
    (e.g. after an offset). ``leftover_ticks`` / ``leftover_other``: frames after one input ended.
    """

    pairs: int = 0
    repeated: int = 0
    dropped: int = 0
    unpaired_ticks_start: int = 0
    unpaired_other_start: int = 0
    leftover_ticks: int = 0
    leftover_other: int = 0

    def as_dict(self) -> dict[str, int]:
        return asdict(self)


def _identity(x):
    return x


def pair_by_time(
    ticks: Iterable[T],
    others: Iterable[U],
    other_period_s: Real,
    time_s: Callable[[T | U], Real] = _identity,
    stats: PairingStats | None = None,
) -> Iterator[tuple[T, U]]:
    """Yield ``(tick, other)`` pairs, ``other`` being the frame of ``others`` nearest in time.

    Both streams must be in increasing time order; they are consumed lazily (one frame of lookahead
    on ``others``), so decoder threads can feed them. ``other_period_s`` is the other stream's frame
    interval: a tick more than half of it before the other's first frame waits for it (unpaired at
    start), and a tick more than half of it after the other's last frame ends the pairing (the
    other input has ended). When either stream ends, what remains of the other one is counted
    (drained) into ``stats.leftover_*``.
    """
    stats = PairingStats() if stats is None else stats
    half_period = other_period_s / 2
    tick_iter, other_iter = iter(ticks), iter(others)
    cur = next(other_iter, None)
    if cur is None:
        stats.leftover_ticks += sum(1 for _ in tick_iter)
        return
    nxt = next(other_iter, None)
    cur_index, used_index = 0, None
    for tick in tick_iter:
        t = time_s(tick)
        # Move to the nearest other frame; strict "<" keeps the earlier frame on an exact tie.
        while nxt is not None and abs(time_s(nxt) - t) < abs(time_s(cur) - t):
            if cur_index != used_index:
                if used_index is None:
                    stats.unpaired_other_start += 1
                else:
                    stats.dropped += 1
            cur, cur_index, nxt = nxt, cur_index + 1, next(other_iter, None)
        if used_index is None and t < time_s(cur) - half_period:
            stats.unpaired_ticks_start += 1
            continue
        if nxt is None and t > time_s(cur) + half_period:
            stats.leftover_ticks += 1 + sum(1 for _ in tick_iter)
            break
        if cur_index == used_index:
            stats.repeated += 1
        used_index = cur_index
        stats.pairs += 1
        yield tick, cur
    stats.leftover_other += int(cur_index != used_index) + int(nxt is not None) + sum(1 for _ in other_iter)


def pair_times(
    times_ticks: Sequence[Real], times_other: Sequence[Real], other_period_s: Real
) -> tuple[list[tuple[int, int]], PairingStats]:
    """Pair two lists of frame times; return ``[(tick_index, other_index), ...]`` and the counts.

    The list form of :func:`pair_by_time` (same rule), for planning and tests.
    """
    stats = PairingStats()
    pairs = pair_by_time(
        enumerate(times_ticks), enumerate(times_other), other_period_s, time_s=lambda item: item[1], stats=stats
    )
    return [(i, j) for (i, _), (j, _) in pairs], stats
