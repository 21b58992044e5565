"""Pairing by presentation time on synthetic timestamp lists, with exact expected pairs and counts."""

from __future__ import annotations

from fractions import Fraction

from sena_warp.video.pairing import PairingStats, pair_by_time, pair_times


def times(n: int, fps: int, start: Fraction = Fraction(0)) -> list[Fraction]:
    return [start + Fraction(k, fps) for k in range(n)]


def test_same_rate_pairs_index_to_index_and_counts_leftover():
    # rooftop-like: the second input has 3 more frames; they are left over, nothing dropped.
    pairs, stats = pair_times(times(10, 30), times(13, 30), Fraction(1, 30))
    assert pairs == [(k, k) for k in range(10)]
    assert stats == PairingStats(pairs=10, leftover_other=3)


def test_ticks_outlast_other_stop_when_it_ends():
    pairs, stats = pair_times(times(13, 30), times(10, 30), Fraction(1, 30))
    assert pairs == [(k, k) for k in range(10)]
    assert stats == PairingStats(pairs=10, leftover_ticks=3)


def test_30_ticks_against_24_fps_repeats_six_per_second():
    # tick k at k/30 s, nearest 24 fps frame is round(0.8 k) (never a tie: 8k = 10n + 5 has no solution).
    pairs, stats = pair_times(times(30, 30), times(24, 24), Fraction(1, 24))
    assert pairs == [(k, round(Fraction(4, 5) * k)) for k in range(30)]
    assert [j for _, j in pairs][:10] == [0, 1, 2, 2, 3, 4, 5, 6, 6, 7]
    assert stats == PairingStats(pairs=30, repeated=6, dropped=0)


def test_24_ticks_against_30_fps_drops_six_per_second_and_ties_take_the_earlier():
    pairs, stats = pair_times(times(24, 24), times(30, 30), Fraction(1, 30))
    # tick k at k/24 s is nearest frame 1.25 k; k = 2 mod 4 is an exact tie (x.5) -> the earlier frame.
    assert [j for _, j in pairs][:8] == [0, 1, 2, 4, 5, 6, 7, 9]
    assert [i for i, _ in pairs] == list(range(24))
    dropped = sorted(set(range(30)) - {j for _, j in pairs})
    assert dropped == [3, 8, 13, 18, 23, 28]
    assert stats == PairingStats(pairs=24, dropped=6)


def test_positive_offset_waits_for_the_second_input():
    # second input shifted +0.2 s (6 frames at 30 fps): the first 6 ticks have no partner.
    pairs, stats = pair_times(times(20, 30), times(20, 30, start=Fraction(1, 5)), Fraction(1, 30))
    assert pairs == [(k, k - 6) for k in range(6, 20)]
    assert stats == PairingStats(pairs=14, unpaired_ticks_start=6, leftover_other=6)


def test_negative_offset_skips_the_second_inputs_head():
    pairs, stats = pair_times(times(20, 30), times(20, 30, start=Fraction(-1, 10)), Fraction(1, 30))
    assert pairs == [(k, k + 3) for k in range(17)]
    assert stats == PairingStats(pairs=17, unpaired_other_start=3, leftover_ticks=3)


def test_sub_frame_offset_keeps_nearest_and_jitter_free():
    # 0.4 frame late: every tick still takes the same-index frame (nearest), no drops or repeats.
    pairs, stats = pair_times(times(10, 30), times(10, 30, start=Fraction(2, 150)), Fraction(1, 30))
    assert pairs == [(k, k) for k in range(10)]
    assert stats == PairingStats(pairs=10)


def test_missing_frame_in_other_is_a_repeat_and_empty_other_pairs_nothing():
    other = [t for k, t in enumerate(times(10, 30)) if k != 4]  # frame 4 lost
    pairs, stats = pair_times(times(10, 30), other, Fraction(1, 30))
    # tick 4 is halfway between frames 3 and 5 (list index 3 and 4): tie -> earlier, a repeat.
    assert [j for _, j in pairs] == [0, 1, 2, 3, 3, 4, 5, 6, 7, 8]
    assert stats == PairingStats(pairs=10, repeated=1)
    pairs, stats = pair_times(times(5, 30), [], Fraction(1, 30))
    assert pairs == [] and stats == PairingStats(leftover_ticks=5)


def test_streaming_form_consumes_lazily_with_objects():
    stats = PairingStats()
    ticks = ({"t": t, "name": f"L{k}"} for k, t in enumerate(times(4, 30)))
    others = ({"t": t, "name": f"R{k}"} for k, t in enumerate(times(4, 30)))
    names = [(a["name"], b["name"]) for a, b in pair_by_time(ticks, others, Fraction(1, 30), lambda f: f["t"], stats)]
    assert names == [("L0", "R0"), ("L1", "R1"), ("L2", "R2"), ("L3", "R3")]
    assert stats.as_dict()["pairs"] == 4
