"""RP_PREVIEW (issue 27): a `RoadPreview` goes out as the multiplexed pages of one snapshot,
cantools and `OutputDecoder` decode every signal within half a step, and `PreviewAssembler`
rebuilds the preview (NaN bins stay NaN) or drops a snapshot with a page missing."""

from __future__ import annotations

import math
from pathlib import Path
from typing import cast

import can
import numpy as np
import pytest
from cantools.database.can import Database

from roadpreview.canbus import (
    RP_PREVIEW,
    OutputDecoder,
    OutputEncoders,
    PreviewAssembler,
    PreviewEncoder,
    ReceivedPreviewHeader,
    ReceivedPreviewPage,
    check_protected,
    load_database,
    read_can_log,
    write_can_log,
)
from roadpreview.canbus.output import (
    PREVIEW_BINS_PER_PAGE,
    PREVIEW_CYCLE_MODULUS,
    PREVIEW_MAX_BINS,
    preview_page_count,
)
from roadpreview.errors import InputDataError
from roadpreview.types import FusionMode, RoadPreview, Status

HEIGHT_LSB_MM = 2.0
STD_LSB_MM = 4.0
STD_MAX_MM = 28.0
FRAME_T = 100.0  #: the frames' time stamp
AGE_S = 0.04  #: the preview is this old when sent


@pytest.fixture(scope="module")
def db() -> Database:
    return load_database()


def _preview(
    bins: int, *, sides: bool, seed: int = 0, nan_share: float = 0.1, t_s: float = FRAME_T - AGE_S
) -> RoadPreview:
    """A road of bumps and holes (within ±0.2 m), stds 0..35 mm, some bins without estimate."""
    rng = np.random.default_rng(seed)
    tracks = 2 if sides else 1
    height = rng.uniform(-0.2, 0.2, (tracks, bins))
    std = rng.uniform(0.0, 0.035, (tracks, bins))
    height[rng.random((tracks, bins)) < nan_share] = np.nan
    std[rng.random((tracks, bins)) < nan_share / 2] = np.nan  # no std: no estimate either
    return RoadPreview(
        t_s=t_s,
        bin_m=0.5,
        start_m=0.35,
        height_m=height,
        std_m=std,
        sides=sides,
        lead_rear_axle_m=0.35 + 0.5 * bins + 0.27,
    )


def _frames(preview: RoadPreview, encoder: PreviewEncoder | None = None) -> list[can.Message]:
    return (encoder or PreviewEncoder()).encode(preview, timestamp=FRAME_T)


def _assert_same_preview(got: RoadPreview, want: RoadPreview, *, bins: int | None = None) -> None:
    n = want.height_m.shape[1] if bins is None else bins
    assert got.sides == want.sides
    assert got.height_m.shape == got.std_m.shape == (want.height_m.shape[0], n)
    assert got.bin_m == pytest.approx(want.bin_m, abs=0.025)
    assert got.start_m == pytest.approx(want.start_m, abs=0.025)
    assert got.lead_rear_axle_m == pytest.approx(want.lead_rear_axle_m, abs=0.05)
    valid = want.valid[:, :n]
    np.testing.assert_array_equal(got.valid, valid)  # NaN bins stay NaN, the others do not
    assert np.isnan(got.height_m[~valid]).all()
    assert np.isnan(got.std_m[~valid]).all()
    h_err = np.abs(got.height_m[valid] - want.height_m[:, :n][valid])
    assert h_err.max(initial=0.0) <= HEIGHT_LSB_MM / 2 * 1e-3 + 1e-12  # half a step
    sd_want = np.minimum(want.std_m[:, :n][valid], STD_MAX_MM * 1e-3)  # 28 mm: at least that
    sd_err = np.abs(got.std_m[valid] - sd_want)
    assert sd_err.max(initial=0.0) <= STD_LSB_MM / 2 * 1e-3 + 1e-12


# --- the DBC -------------------------------------------------------------------------------


def test_the_layout_constants_are_the_dbcs(db: Database) -> None:
    m = db.get_message_by_name(RP_PREVIEW)
    assert m.frame_id == 0x207
    assert m.is_multiplexed()
    page = m.get_signal_by_name("PreviewPage")
    assert page.is_multiplexer
    assert (page.start, page.length) == (12, 6)
    assert m.get_signal_by_name("PreviewBins").maximum == PREVIEW_MAX_BINS
    assert 2 ** m.get_signal_by_name("PreviewCycle").length == PREVIEW_CYCLE_MODULUS
    # the most pages a snapshot has fit the multiplexor and are all defined
    last = preview_page_count(PREVIEW_MAX_BINS, True) - 1
    assert last == page.maximum < 2**page.length
    heights = [s for s in m.signals if s.name.startswith("PreviewHeight")]
    assert len(heights) == PREVIEW_BINS_PER_PAGE
    for s in heights:
        assert s.multiplexer_ids == list(range(1, last + 1))
    for name in ("PreviewBins", "PreviewSides", "PreviewBinLength", "PreviewStart"):
        assert m.get_signal_by_name(name).multiplexer_ids == [0]
    # every page uses at most 64 bits, a bin page all of them
    for mux, width in ((0, 63), (1, 64), (last, 64)):
        here = [s for s in m.signals if s.multiplexer_ids is None or mux in s.multiplexer_ids]
        assert sum(s.length for s in here) == width
        bits = sorted(b for s in here for b in range(s.start, s.start + s.length))
        assert len(bits) == len(set(bits))  # no overlap


# --- the frames ----------------------------------------------------------------------------


@pytest.mark.parametrize(("bins", "sides"), [(37, True), (37, False), (120, True), (1, False)])
def test_every_signal_decodes_with_cantools_within_half_a_step(
    db: Database, bins: int, sides: bool
) -> None:
    preview = _preview(bins, sides=sides)
    frames = _frames(preview)
    m = db.get_message_by_name(RP_PREVIEW)
    per_track = -(-bins // PREVIEW_BINS_PER_PAGE)
    assert len(frames) == preview_page_count(bins, sides) == 1 + (2 if sides else 1) * per_track
    assert all(f.arbitration_id == 0x207 and f.dlc == 8 and not f.is_extended_id for f in frames)
    assert all(f.timestamp == FRAME_T for f in frames)
    decoded = [cast(dict[str, object], db.decode_message(0x207, bytes(f.data))) for f in frames]
    assert all(check_protected(m, f.data) for f in frames)
    counters = [d["RpPreview_Counter"] for d in decoded]
    assert counters == [k % 15 for k in range(len(frames))]  # +1 per page, 0..14
    assert [d["PreviewPage"] for d in decoded] == list(range(len(frames)))  # header first
    assert {d["PreviewCycle"] for d in decoded} == {0}

    head = decoded[0]
    assert head["PreviewBins"] == bins
    assert str(head["PreviewSides"]) == ("LEFT_RIGHT" if sides else "ONE_TRACK")
    assert head["PreviewBinLength"] == pytest.approx(preview.bin_m, abs=0.025)
    assert head["PreviewStart"] == pytest.approx(preview.start_m, abs=0.025)
    assert head["PreviewLeadRearAxle"] == pytest.approx(preview.lead_rear_axle_m, abs=0.05)
    assert head["PreviewAge"] == pytest.approx(AGE_S, abs=0.005)

    # bins back from the pages: the first track's pages, then the second's, 4 bins a page
    tracks = 2 if sides else 1
    h_mm = np.full((tracks, per_track * 4), np.nan)
    sd_mm = np.full_like(h_mm, np.nan)
    for k, d in enumerate(decoded[1:]):
        track, first = divmod(k, per_track)
        for i in range(PREVIEW_BINS_PER_PAGE):
            h = d[f"PreviewHeight{i}"]
            if str(h) != "SignalNotAvailable":
                h_mm[track, 4 * first + i] = cast(float, h)
                sd_mm[track, 4 * first + i] = cast(float, d[f"PreviewStd{i}"])
            else:
                assert d[f"PreviewStd{i}"] == STD_MAX_MM
    assert np.isnan(h_mm[:, bins:]).all()  # slots after the last bin: not available
    valid = preview.valid
    np.testing.assert_array_equal(np.isfinite(h_mm[:, :bins]), valid)
    h_err = np.abs(h_mm[:, :bins][valid] - 1e3 * preview.height_m[valid])
    assert h_err.max(initial=0.0) <= HEIGHT_LSB_MM / 2 + 1e-9
    sd_want = np.minimum(1e3 * preview.std_m[valid], STD_MAX_MM)
    assert np.abs(sd_mm[:, :bins][valid] - sd_want).max(initial=0.0) <= STD_LSB_MM / 2 + 1e-9


def test_output_decoder_gives_header_and_pages(db: Database) -> None:
    preview = _preview(10, sides=True)
    decoder = OutputDecoder(db)
    got = [decoder.decode(f) for f in _frames(preview)]
    head, pages = got[0], got[1:]
    assert isinstance(head, ReceivedPreviewHeader)
    assert (head.bins, head.sides, head.cycle, head.pages) == (10, True, 0, 6)
    assert head.age_s == pytest.approx(AGE_S, abs=0.005)
    assert head.t_preview_s == pytest.approx(preview.t_s, abs=0.005)
    assert all(isinstance(p, ReceivedPreviewPage) for p in pages)
    page = cast(ReceivedPreviewPage, pages[3])  # the right track's first page: bins 0..3
    assert page.page == 4
    for i in range(4):
        want = preview.height_m[1, i] if preview.valid[1, i] else math.nan
        assert page.height_m[i] == pytest.approx(want, abs=1e-3, nan_ok=True)
    assert decoder.problems == {}
    assert decoder.lost == 0


def test_out_of_range_values_saturate_and_are_counted() -> None:
    height = np.array([[0.4, -0.4, 0.1, 0.0, 0.2535]])
    std = np.array([[0.001, 0.05, 0.0, 0.02, 0.0]])
    preview = RoadPreview(0.0, 0.5, 100.0, height, std, False, 300.0)
    enc = PreviewEncoder()
    frames = enc.encode(preview, timestamp=5.0)  # 5 s old: the age saturates too
    back = PreviewAssembler()
    got = [back.push_frame(f) for f in frames][-1]
    assert got is not None
    np.testing.assert_allclose(got.height_m, [[0.254, -0.254, 0.1, 0.0, 0.254]], atol=1e-9)
    np.testing.assert_allclose(got.std_m, [[0.0, 0.028, 0.0, 0.020, 0.0]], atol=1e-9)
    assert got.start_m == pytest.approx(25.55)
    assert got.lead_rear_axle_m == pytest.approx(204.6)
    assert got.t_s == pytest.approx(5.0 - 2.54)
    assert enc.saturated["PreviewHeight"] == 2  # 0.2535 rounds to 254 mm: in range
    assert enc.saturated["PreviewStd"] == 1
    assert enc.saturated["PreviewStart"] == enc.saturated["PreviewLeadRearAxle"] == 1
    assert enc.saturated["PreviewAge"] == 1


def test_a_track_longer_than_the_cap_loses_its_far_bins() -> None:
    preview = _preview(150, sides=True)
    enc = PreviewEncoder()
    frames = enc.encode(preview, timestamp=FRAME_T)
    assert len(frames) == 61  # the most a snapshot has: header + 2 x 30 pages
    assert enc.truncated == 1
    got = PreviewAssembler().push_frame(frames[0])
    assert got is None
    asm = PreviewAssembler()
    out = [asm.push_frame(f) for f in frames]
    assert out[-1] is not None
    _assert_same_preview(out[-1], preview, bins=PREVIEW_MAX_BINS)
    # a lower cap for a busy bus
    short = PreviewEncoder(max_bins=40).encode(preview, timestamp=FRAME_T)
    assert len(short) == 1 + 2 * 10


def test_a_malformed_preview_is_refused() -> None:
    ok = _preview(8, sides=True)
    one_row = RoadPreview(0.0, 0.5, 0.0, ok.height_m[:1], ok.std_m[:1], True, 5.0)
    with pytest.raises(InputDataError, match=r"height_m.*sides=True"):
        PreviewEncoder().encode(one_row)
    mismatched = RoadPreview(0.0, 0.5, 0.0, ok.height_m, ok.std_m[:, :4], True, 5.0)
    with pytest.raises(InputDataError, match="std_m"):
        PreviewEncoder().encode(mismatched)
    with pytest.raises(InputDataError, match="bin_m"):
        PreviewEncoder().encode(RoadPreview(0.0, 0.0, 0.0, ok.height_m, ok.std_m, True, 5.0))


# --- assembling ----------------------------------------------------------------------------


@pytest.mark.parametrize(("bins", "sides"), [(0, False), (1, True), (37, True), (120, False)])
def test_the_pages_reassemble_to_the_same_preview(bins: int, sides: bool) -> None:
    preview = _preview(bins, sides=sides, seed=bins)
    asm = PreviewAssembler()
    out = [asm.push_frame(f) for f in _frames(preview)]
    assert all(p is None for p in out[:-1])  # only the last page completes it
    got = out[-1]
    assert got is not None
    _assert_same_preview(got, preview)
    assert got.t_s == pytest.approx(preview.t_s, abs=0.005)
    assert asm.completed == 1
    assert asm.dropped == {}


def test_a_lost_page_drops_that_snapshot_only() -> None:
    enc = PreviewEncoder()
    previews = [_preview(20, sides=True, seed=s, t_s=FRAME_T + 0.1 * s) for s in range(5)]
    snapshots = [enc.encode(p, timestamp=p.t_s) for p in previews]
    assert [cast(dict[str, int], enc.db.decode_message(0x207, bytes(s[0].data)))["PreviewCycle"]
            for s in snapshots] == [0, 1, 2, 3, 0]  # fmt: skip
    del snapshots[1][4]  # a bin page of snapshot 1
    del snapshots[3][-1]  # the last page of snapshot 3: noticed at the next header
    asm = PreviewAssembler()
    got = [p for frame in (f for s in snapshots for f in s) if (p := asm.push_frame(frame))]
    assert len(got) == 3
    for g, want in zip(got, (previews[0], previews[2], previews[4]), strict=True):
        _assert_same_preview(g, want)
        assert g.t_s == pytest.approx(want.t_s, abs=0.005)
    assert asm.dropped == {"missing_page": 2}
    assert asm.decoder.lost == 2  # the E2E counter saw both


def test_pages_without_their_header_are_dropped() -> None:
    enc = PreviewEncoder()
    previews = [_preview(12, sides=False, seed=s) for s in range(3)]
    snapshots = [enc.encode(p, timestamp=FRAME_T) for p in previews]
    del snapshots[1][0]  # the header of snapshot 1
    asm = PreviewAssembler()
    got = [p for frame in (f for s in snapshots for f in s) if (p := asm.push_frame(frame))]
    assert len(got) == 2
    _assert_same_preview(got[1], previews[2])
    assert asm.dropped == {"no_header": 1}
    # a header lost while a snapshot is open: its pages (the next cycle) close the open one
    asm = PreviewAssembler()
    s0, s1 = (enc.encode(p, timestamp=FRAME_T) for p in previews[:2])
    for f in [*s0[:-1], *s1[1:]]:
        assert asm.push_frame(f) is None
    assert asm.dropped == {"missing_page": 1, "no_header": 1}


def test_a_corrupted_page_drops_its_snapshot() -> None:
    frames = _frames(_preview(16, sides=False))
    bad = frames[2]
    data = bytearray(bad.data)
    data[5] ^= 0x10
    frames[2] = can.Message(arbitration_id=0x207, data=bytes(data), is_extended_id=False)
    asm = PreviewAssembler()
    assert [asm.push_frame(f) for f in frames] == [None] * len(frames)
    assert asm.decoder.problems["crc"] == 1


def test_other_frames_between_the_pages_do_not_matter() -> None:
    encoders = OutputEncoders()
    preview = _preview(24, sides=True)
    frames = encoders.preview_frames(preview, timestamp=FRAME_T)
    status = encoders.status_frames(Status(mode=FusionMode.FUSED), timestamp=FRAME_T)
    mixed = [frames[0], *status, *frames[1:5], status[0], *frames[5:]]
    asm = PreviewAssembler()
    got = [p for f in mixed if (p := asm.push_frame(f))]
    assert len(got) == 1
    _assert_same_preview(got[0], preview)
    assert got[0].t_s == pytest.approx(preview.t_s, abs=0.005)


@pytest.mark.parametrize("suffix", [".blf", ".asc"])
def test_a_logged_preview_reassembles(tmp_path: Path, suffix: str) -> None:
    t_unix = 1.7e9  # BLF keeps calendar time
    preview = _preview(50, sides=True, t_s=t_unix - AGE_S)
    path = tmp_path / f"preview{suffix}"
    frames = PreviewEncoder().encode(preview, timestamp=t_unix)
    assert write_can_log(path, frames) == len(frames)
    asm = PreviewAssembler()
    got = [p for f in read_can_log(path) if (p := asm.push_frame(f))]
    assert len(got) == 1
    _assert_same_preview(got[0], preview)
