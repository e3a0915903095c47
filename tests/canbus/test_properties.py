"""Property tests (hypothesis) of the inputs: the CAN decoder, the IMU CSV reader and the
mapping. Whatever comes in: no exception escapes (only the documented ConfigError /
InputDataError naming the file), every accepted sample is finite (or NaN where the sender
says "not available") and inside the car's physical range, and a message's time never
goes backwards out of the decoder (except at a counted ``resynced``)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import can
import e2e.p01
import pytest
from cantools.database.can import Database
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from roadpreview.canbus import CanInputDecoder, encode_protected, load_database, load_mapping
from roadpreview.canbus.imu_csv import IMU_CSV_COLUMNS, imu_samples, read_imu_csv
from roadpreview.canbus.mapping import QUANTITIES, parse_mapping
from roadpreview.errors import ConfigError, InputDataError
from roadpreview.plausibility import ACCEL_QUANTITIES, RATE_QUANTITIES, PlausibilityConfig
from roadpreview.types import ImuSample, InputSample

LIMITS = PlausibilityConfig()
SETTINGS = settings(
    max_examples=60,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
OUR_IDS = (0x130, 0x131, 0x140, 0x141)


@pytest.fixture(scope="module")
def db() -> Database:
    database: Database = load_database()
    return database


def _assert_plausible(sample: InputSample) -> None:
    assert math.isfinite(sample.t_s)
    if isinstance(sample, ImuSample):
        pairs = zip(
            RATE_QUANTITIES + ACCEL_QUANTITIES, sample.rates_rad_s + sample.accel_m_s2, strict=True
        )
        for q, v in pairs:
            assert math.isnan(v) or (math.isfinite(v) and LIMITS.in_range(q, v)), (q, v)
    else:
        v = sample.speed_mps
        assert math.isnan(v) or (math.isfinite(v) and LIMITS.in_range("speed", v)), v


@st.composite
def frames(draw: st.DrawFn) -> list[can.Message]:
    """Frames of our IDs and others, random payloads (half with a valid E2E CRC), random
    lengths, flags and stamps (mostly advancing, some NaN, inf, jumps and steps back)."""
    out = []
    t = 0.0
    for _ in range(draw(st.integers(1, 60))):
        fid = draw(st.sampled_from(OUR_IDS) | st.integers(0, 0x7FF))
        n = draw(st.sampled_from([8, 8, 8, 8, 0, 6, 7, 12]))
        data = bytearray(draw(st.binary(min_size=n, max_size=n)))
        if n == 8 and draw(st.booleans()):
            data[1] = (data[1] & 0xF0) | draw(st.integers(0, 15))
            e2e.p01.e2e_p01_protect(data, fid, increment_counter=False)
        step = draw(
            st.sampled_from([0.01, 0.01, 0.01, 0.0, -0.005, 3600.0, -10.0, math.nan, math.inf])
        )
        stamp = t + step
        if math.isfinite(stamp):
            t = stamp
        out.append(
            can.Message(
                timestamp=stamp,
                arbitration_id=fid,
                data=bytes(data),
                is_extended_id=draw(st.sampled_from([False, False, False, True])),
                is_fd=n > 8,
                is_error_frame=draw(st.sampled_from([False] * 15 + [True])),
            )
        )
    return out


@SETTINGS
@given(stream=frames())
def test_decoder_never_raises_and_gives_only_plausible_samples_in_time_order(
    db: Database, stream: list[can.Message]
) -> None:
    dec = CanInputDecoder(db, load_mapping("roadpreview"))
    last: dict[str, float] = {}
    for msg in stream:
        resynced = dec.problems["resynced"]
        out = dec.decode(msg)
        stepped_back = dec.problems["resynced"] > resynced
        for s in out:
            _assert_plausible(s)
            if not stepped_back:
                assert s.t_s > last.get(s.source, -math.inf)
            last[s.source] = s.t_s
    assert dec.stats.frames == len(stream)
    assert dec.stats.used + dec.stats.skipped + dec.stats.ignored == len(stream)


_NUMBER = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.floats(-50.0, 50.0),
    st.sampled_from([1e6, -1e6, 9.81, 0.0]),
)


@st.composite
def csv_rows(draw: st.DrawFn) -> list[str]:
    rows = []
    t = 0.0
    for _ in range(draw(st.integers(0, 40))):
        t += draw(st.sampled_from([0.01, 0.01, 0.0, -0.02, 5.0]))
        values = [t, *(draw(_NUMBER) for _ in range(6))]
        cells = [repr(v) for v in values]
        if draw(st.integers(0, 9)) == 0:
            cells = [*cells[: draw(st.integers(0, 7))], draw(st.sampled_from(["", "x", "nan"]))]
        rows.append(",".join(cells))
    return rows


@SETTINGS
@given(rows=csv_rows())
def test_imu_csv_reader_never_raises_but_names_the_file_and_keeps_only_plausible_rows(
    tmp_path: Path, rows: list[str]
) -> None:
    path = tmp_path / "imu.csv"
    path.write_text("\n".join([",".join(IMU_CSV_COLUMNS), *rows]) + "\n")
    try:
        table = read_imu_csv(path)
    except InputDataError as exc:
        error = str(exc)
    else:
        error = ""
    if error:
        assert str(path) in error
        return
    samples = imu_samples(table, str(path))
    for s in samples:
        _assert_plausible(s)
    stamps = [s.t_s for s in samples]
    assert stamps == sorted(set(stamps))


_FIELD_VALUES: dict[str, Any] = {
    "message": st.sampled_from(["IMU_RATES", "IMU_ACCEL", "VEHICLE_SPEED", "NOPE", ""]),
    "signal": st.sampled_from(["RollRate", "PitchRate", "AccelZ", "VehicleSpeed", "X", ""]),
    "unit": st.sampled_from(["deg/s", "rad/s", "m/s^2", "g", "km/h", "furlong", ""]),
    "axis": st.sampled_from(["x", "y", "z", "", "w"]),
    "sign": st.sampled_from([1, -1, 2]),
    "scale": st.floats(allow_nan=True, allow_infinity=True),
    "offset": st.floats(-1e3, 1e3),
    "range": st.lists(st.floats(-1e3, 1e3), min_size=0, max_size=3),
    "missing": st.sampled_from(["", "not on this car"]),
    "bogus": st.just(1),
}


@SETTINGS
@given(
    changes=st.dictionaries(
        st.sampled_from(list(QUANTITIES)),
        st.dictionaries(st.sampled_from(list(_FIELD_VALUES)), st.integers(0, 10**6), max_size=3),
        max_size=3,
    ),
    data=st.data(),
)
def test_mapping_errors_are_config_errors_and_a_mapping_that_loads_decodes_plausibly(
    db: Database, changes: dict[str, dict[str, int]], data: st.DataObject
) -> None:
    base = load_mapping("roadpreview")
    quantities = {q: dict(vars(s)) for q, s in base.quantities.items()}
    for q, fields in changes.items():
        for key in fields:
            quantities[q][key] = data.draw(_FIELD_VALUES[key])
        quantities[q] = {k: v for k, v in quantities[q].items() if v is not None}
    raw = {"mapping": {"name": "prop", "dbc_ranges": True}, "quantities": quantities}
    dec = None
    try:
        dec = CanInputDecoder(db, parse_mapping(raw, source="prop.toml"))
    except ConfigError as exc:
        error = str(exc)
    if dec is None:
        assert "prop.toml" in error
        return

    rates = db.get_message_by_name("IMU_RATES")
    for k in range(5):
        value = data.draw(st.floats(-163.8, 163.8))
        payload = encode_protected(
            rates, {"RollRate": value, "PitchRate": value, "YawRate": value}, k
        )
        for s in dec.decode(
            can.Message(
                timestamp=0.01 * k, arbitration_id=0x130, data=payload, is_extended_id=False
            )
        ):
            _assert_plausible(s)
