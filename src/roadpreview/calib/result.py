"""What ``roadpreview calibrate`` writes and prints: ``camera.toml`` (`CameraModel.save`),
``mapping.toml`` (the input mapping with a ``[mount]`` table, what ``[can] mapping`` of the
pipeline configuration then names), ``calibration.json`` and a table: every estimate with
its uncertainty, the driving it used, and what could not be determined and why.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

from scipy.spatial.transform import Rotation

from roadpreview._tomlio import dump_toml, load_toml
from roadpreview.calib.estimate import Calibration
from roadpreview.canbus.mapping import load_mapping, packaged_mapping_path
from roadpreview.canbus.samples import ImuMount

_AXES = "xyz"


def _num(x: float, nd: int = 6) -> float | None:
    return round(float(x), nd) if math.isfinite(x) else None


def mount_of(cal: Calibration) -> ImuMount | None:
    """The IMU mount the calibration found (None without the full rotation); the time
    offset is 0 when it was not found."""
    if not cal.rotation:
        return None
    tau = cal.time_offset.offset_s if cal.time_offset else 0.0
    return ImuMount(rotation=cal.body_from_imu, time_offset_s=tau)


def report(cal: Calibration) -> dict[str, Any]:
    """``calibration.json``: each estimate, its standard error, what it used, or why not."""
    f, to, ax, rot = cal.forward, cal.time_offset, cal.pitch_axis, cal.rotation
    out: dict[str, Any] = {
        "forward": {
            "t": [_num(v) for v in cal.camera.forward] if f else None,
            "yaw_deg": _num(math.degrees(f.yaw_rad), 3),
            "yaw_std_deg": _num(math.degrees(f.yaw_std_rad), 3),
            "mount_pitch_deg": _num(math.degrees(f.pitch_rad), 3),
            "mount_pitch_std_deg": _num(math.degrees(f.pitch_std_rad), 3),
            "foe_px": [_num(cal.foe_px[0], 2), _num(cal.foe_px[1], 2)] if f else None,
            "horizon_row_px": _num(cal.foe_px[1], 2) if f else None,
            "horizon_row_std_px": _num(cal.camera.fy * f.pitch_std_rad, 2),
            "key_pairs_used": f.n_used,
            "key_pairs_rejected": f.n_rejected,
            "seconds_used": _num(cal.forward_seconds, 2),
            "not_determined": f.reason or None,
        },
        "time_offset": {
            "offset_ms": _num(1e3 * to.offset_s, 2),
            "std_ms": _num(1e3 * to.std_s, 2),
            "r2": _num(to.r2, 3),
            "rotations_used": to.n_increments,
            "seconds_used": _num(to.seconds, 2),
            "not_determined": to.reason or None,
        },
        "pitch_axis": {
            "axis": _AXES[ax.axis] if ax else None,
            "sign": ax.sign if ax else None,
            "correlation": _num(ax.correlation, 3),
            "correlations": [_num(c, 3) for c in ax.correlations],
            "slopes": [_num(c, 3) for c in ax.slopes],
            "samples_used": ax.n_samples,
            "not_determined": ax.reason or None,
        },
        "rotation": {
            "camera_from_imu": rot.R.round(6).tolist() if rot else None,
            "body_from_imu": cal.body_from_imu.round(6).tolist() if rot else None,
            "body_from_imu_ypr_deg": (
                [
                    _num(a, 3)
                    for a in Rotation.from_matrix(cal.body_from_imu).as_euler("ZYX", degrees=True)
                ]
                if rot
                else None
            ),
            "std_deg": _num(rot.std_deg, 3),
            "excitation_deg_s": [_num(math.degrees(e), 3) for e in rot.excitation_rad_s],
            "residual_deg_s": _num(math.degrees(rot.residual_rad_s), 3),
            "samples_used": rot.n_samples,
            "not_determined": rot.reason or None,
        },
        "imu": {"samples": cal.imu_samples, "seconds": _num(cal.imu_seconds, 2)},
        "camera_rotations": cal.rotations,
    }
    return out


def table(cal: Calibration) -> str:
    """The report as a table for the terminal."""
    r = report(cal)
    rows: list[tuple[str, str, str, str]] = []

    def row(name: str, value: str, std: str, used: str) -> None:
        rows.append((name, value, std, used))

    fw, to, ax, rot = r["forward"], r["time_offset"], r["pitch_axis"], r["rotation"]
    used_fw = f"{fw['key_pairs_used']} pairs, {fw['seconds_used']} s"
    if cal.forward:
        row("forward yaw", f"{fw['yaw_deg']:+.2f} deg", f"{fw['yaw_std_deg']:.2f} deg", used_fw)
        row(
            "mounting pitch",
            f"{fw['mount_pitch_deg']:+.2f} deg",
            f"{fw['mount_pitch_std_deg']:.2f} deg",
            used_fw,
        )
        row(
            "horizon row",
            f"{fw['horizon_row_px']:.1f} px",
            f"{fw['horizon_row_std_px']:.1f} px",
            used_fw,
        )
    else:
        row("forward direction", "not determined", "", cal.forward.reason)
    used_to = f"{to['rotations_used']} rotations, {to['seconds_used']} s"
    if cal.time_offset:
        row("IMU time offset", f"{to['offset_ms']:+.1f} ms", f"{to['std_ms']:.1f} ms", used_to)
    else:
        row("IMU time offset", "not determined", "", cal.time_offset.reason)
    if cal.pitch_axis:
        sign = "+" if ax["sign"] > 0 else "-"
        row(
            "pitch rate axis",
            f"{sign}gyro_{ax['axis']}",
            f"corr {ax['correlation']:.3f}",
            f"{ax['samples_used']} rates",
        )
    else:
        row("pitch rate axis", "not determined", "", cal.pitch_axis.reason)
    if cal.rotation:
        ypr = rot["body_from_imu_ypr_deg"]
        row(
            "IMU mount (y,p,r)",
            f"{ypr[0]:+.1f} {ypr[1]:+.1f} {ypr[2]:+.1f} deg",
            f"{rot['std_deg']:.2f} deg",
            f"{rot['samples_used']} rates",
        )
    else:
        row("IMU rotation", "not determined", "", cal.rotation.reason)
    w = [max(len(x[i]) for x in rows) for i in range(3)]
    head = f"{'estimate':{w[0]}}  {'value':{w[1]}}  {'std':{w[2]}}  used / why not"
    lines = [head] + [f"{a:{w[0]}}  {b:{w[1]}}  {c:{w[2]}}  {d}" for a, b, c, d in rows]
    return "\n".join(lines)


def write_outputs(cal: Calibration, out: str | Path, mapping: str = "roadpreview") -> list[Path]:
    """``camera.toml``, ``calibration.json`` and, when the IMU's rotation was found,
    ``mapping.toml``: the input ``mapping`` (a file or a shipped name) with the ``[mount]``."""
    folder = Path(out)
    folder.mkdir(parents=True, exist_ok=True)
    written = [folder / "camera.toml", folder / "calibration.json"]
    cal.camera.save(written[0])
    written[1].write_text(json.dumps(report(cal), indent=2))
    mount = mount_of(cal)
    if mount is not None:
        src = Path(mapping)
        if isinstance(mapping, str) and src.suffix == "" and len(src.parts) == 1:
            src = packaged_mapping_path(mapping)
        data = dict(load_toml(src))
        data["mount"] = mount.to_dict()
        path = folder / "mapping.toml"
        dump_toml(data, path)
        load_mapping(path)  # what the product will read: checked now
        written.append(path)
    return written


__all__ = ["mount_of", "report", "table", "write_outputs"]
