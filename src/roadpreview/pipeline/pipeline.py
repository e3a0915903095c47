"""`Pipeline`: typed samples in (`roadpreview.types`: camera frames, IMU and speed samples,
in time-stamp order), trajectory, pitch, modes, detector output and alerts out. It knows
no CAN, no files and no clocks: sources decode and stamp the samples, the run loop
(`roadpreview.pipeline.loop`) orders them, sinks write what comes out. The same object
serves replay, the daemon, the evaluation and the demo.

Per frame (``push`` of a `CameraFrame`):

1. vision: lead observation y(t) (and halves, box, distance) and background
   correspondences against the current key frame, with a texture measure;
2. pitch: the robust estimator on the key-frame correspondences (relative
   pitch since the key frame; warm start reset when the key frame is renewed);
3. fusion: the visual measurement (or a vision failure) with the gyro samples
   pushed so far -> φ(t), its std, the mode, the gyro bias, the time offset;
4. compensation ``y_c = y - f tan φ - f Δz_cam / d`` (paper eq. 4 plus the camera's heave
   Δz_cam from the accelerometer over the lead's distance d; the term held while either
   is unknown), also for the halves: one stage, `roadpreview.compensation.Compensator`;
5. detector: s(t) (paper eq. 1), threshold, NMS -> events -> alerts.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field, replace
from typing import overload

from roadpreview.anomaly import AlertBuilder, TrajectorySample, make_detector
from roadpreview.anomaly.base import AnomalyEvent
from roadpreview.anomaly.confirm import EgoConfirmer
from roadpreview.anomaly.roughness import RoadRoughness
from roadpreview.camera import CameraModel
from roadpreview.compensation import Compensator
from roadpreview.ego.kinematics import EgoSpeed, HorizonFilter, LeadKinematics
from roadpreview.ego.vertical import EgoVerticalMonitor
from roadpreview.fusion import FusedPitch, VisualPitch, make_fusion
from roadpreview.pipeline.config import PipelineConfig
from roadpreview.pitch import PitchEstimator, make_estimator
from roadpreview.preview import ProfileEstimator
from roadpreview.types import (
    Alert,
    CameraFrame,
    Confirmation,
    ConfirmationResult,
    FusionMode,
    ImuSample,
    RoadPreview,
    RoadState,
    Sample,
    SpeedSample,
    Status,
    SuppressionReason,
)
from roadpreview.vision.frontend import FrameVision, VisionFrontEnd

log = logging.getLogger(__name__)

#: the frame hold shrinks by at most this per frame (`Pipeline.frame_hold_s`), s: less than
#: any frame interval, so that frames never fall due together
HOLD_STEP_S = 0.005


@dataclass(frozen=True)
class FrameResult:
    """Everything the pipeline knows about one frame."""

    t: float
    index: int
    y: float
    y_left: float
    y_right: float
    y_c: float
    phi: float
    phi_std: float
    mode: FusionMode
    bias: float
    time_offset: float
    s: float
    s_left: float
    s_right: float
    threshold_px: float
    suppressed: SuppressionReason
    lead_found: bool
    lead_distance_m: float
    lead_box: tuple[float, float, float, float] | None
    n_lead_points: int
    n_background: int
    textured: bool
    vision_reason: str
    pitch_reason: str
    target_changed: bool
    lead_accel_mps2: float | None
    ego_speed_mps: float | None
    #: the camera's heave Δz_cam (m, up +) at the frame; NaN: unavailable (no accelerometer,
    #: warming up after a gap, or heave compensation disabled)
    heave_m: float = math.nan
    #: the heave term subtracted from y (px): f (Δz_cam - Δz_on) / d plus the value it had
    #: when it resumed (Δz_on), so it never jumps; held constant while the heave or the
    #: lead distance is unknown; 0 before the first and after a target change
    heave_px: float = 0.0
    #: the detector's statistic, its threshold and the time it describes (``DetectorFrame``)
    score: float = math.nan
    score_threshold: float = math.nan
    score_t: float = math.nan
    #: the detector's fitted road input at this frame and its background, m (NaN: none)
    road_input_m: float = math.nan
    background_m: float = math.nan
    #: the ego's band-passed vertical acceleration peak over the frame interval, m/s²
    ego_accel_peak_mps2: float = math.nan
    road: RoadState = field(default_factory=RoadState)  #: the road's roughness class estimate
    #: what the detector was given at this frame (None: not run)
    sample: TrajectorySample | None = None
    events: tuple[AnomalyEvent, ...] = ()
    #: CONFIRMED alerts raised at this frame (a provisional one confirmed keeps its id)
    alerts: tuple[Alert, ...] = ()
    #: PROVISIONAL alerts raised at this frame (the lead's front axle: docs/detector.md)
    provisional: tuple[Alert, ...] = ()
    #: provisional alerts cancelled at this frame (the two-axle fit did not confirm them)
    cancelled: tuple[Alert, ...] = ()
    #: the road-profile preview made at this frame (every ``[preview] period_s``), else None
    preview: RoadPreview | None = None
    #: alerts whose spot the ego passed at this frame, with what it felt there
    confirmations: tuple[ConfirmationResult, ...] = ()

    #: columns of the per-frame table, in order
    COLUMNS = (
        "t",
        "index",
        "y",
        "y_left",
        "y_right",
        "y_c",
        "phi",
        "phi_std",
        "mode",
        "bias",
        "time_offset",
        "s",
        "s_left",
        "s_right",
        "threshold_px",
        "suppressed",
        "lead_found",
        "lead_distance_m",
        "n_lead_points",
        "n_background",
        "textured",
        "n_events",
        "heave_m",
        "heave_px",
        "score",
        "score_threshold",
        "score_t",
        "road_input_mm",
        "background_mm",
        "ego_accel_peak_mps2",
        "road_class",
    )

    def row(self) -> list[float | int | str]:
        """The frame as a row of the per-frame table (`COLUMNS`)."""
        return [
            self.t,
            self.index,
            self.y,
            self.y_left,
            self.y_right,
            self.y_c,
            self.phi,
            self.phi_std,
            self.mode.name,
            self.bias,
            self.time_offset,
            self.s,
            self.s_left,
            self.s_right,
            self.threshold_px,
            int(self.suppressed),
            int(self.lead_found),
            self.lead_distance_m,
            self.n_lead_points,
            self.n_background,
            int(self.textured),
            len(self.events),
            self.heave_m,
            self.heave_px,
            self.score,
            self.score_threshold,
            self.score_t,
            1e3 * self.road_input_m,
            1e3 * self.background_m,
            self.ego_accel_peak_mps2,
            self.road.iso_class or "",
        ]


class Pipeline:
    """The streaming estimator (module docstring). Push in timestamp order."""

    def __init__(
        self,
        camera: CameraModel,
        config: PipelineConfig | None = None,
        *,
        pitch: PitchEstimator | None = None,
    ) -> None:
        """``pitch``: an estimator to use instead of the configured one (the evaluation's
        adapters); the configuration's ``[pitch]`` options then do not apply."""
        self.camera = camera
        self.config = config or PipelineConfig()
        cfg = self.config
        self.vision = VisionFrontEnd(camera, cfg.vision)
        self.pitch: PitchEstimator = pitch or make_estimator(
            cfg.pitch.estimator, camera, **cfg.pitch.options
        )
        self.fusion = make_fusion(cfg.fusion.backend, **cfg.fusion.options)
        self.detector = make_detector(cfg.anomaly, camera.fy)
        signal = cfg.anomaly.std.signal
        if signal.focal_px is None:
            signal = replace(signal, focal_px=camera.fy)
        self.alert_builder = AlertBuilder(cfg.anomaly.alert, signal=signal)
        self.ego_vertical = EgoVerticalMonitor(cfg.ego)
        self.roughness = RoadRoughness(cfg.anomaly.roughness, cfg.anomaly.two_axle.vehicle)
        self.confirmer = EgoConfirmer(cfg.anomaly.confirm)
        #: the road-profile preview (``RP_PREVIEW``), from the same trajectory samples
        self.preview = ProfileEstimator(
            cfg.preview, cfg.anomaly.two_axle.vehicle, principal_row_px=camera.cy
        )
        self._lead = LeadKinematics(cfg.lead.window_s)
        self.compensator = Compensator(camera.fy, cfg.heave, cfg.plausibility)
        self._speed = EgoSpeed()
        self._horizon = HorizonFilter(cfg.fusion.horizon_highpass_s)
        self.pitch_divergences = 0  #: frames whose fused pitch was beyond max_pitch_rad
        self._hold_s = math.nan  # the frame hold last given to the run loop
        self._key_index = -1
        self.frames = 0
        self.alerts_sent = 0
        #: samples the sources lost (undecodable, garbled, rejected) so far, for the
        #: status; the run loop keeps it up to date
        self.input_errors = 0
        self.last: FrameResult | None = None

    # -- inputs ---------------------------------------------------------------------
    @overload
    def push(self, sample: CameraFrame) -> FrameResult: ...
    @overload
    def push(self, sample: ImuSample | SpeedSample) -> None: ...
    def push(self, sample: Sample) -> FrameResult | None:
        """Take one sample (in time-stamp order); a camera frame gives its `FrameResult`."""
        if isinstance(sample, CameraFrame):
            return self.push_frame(sample)
        if isinstance(sample, ImuSample):
            self.push_imu(sample)
        else:
            self.push_speed(sample)
        return None

    def push_imu(self, sample: ImuSample) -> None:
        self.compensator.push_imu(sample)
        self.ego_vertical.push(sample.t_s, sample.accel_m_s2[2])
        roll, pitch, yaw = sample.rates_rad_s
        if math.isfinite(pitch):
            self.fusion.push_gyro(
                sample.t_s,
                pitch,
                roll_rate=roll if math.isfinite(roll) else None,
                yaw_rate=yaw if math.isfinite(yaw) else None,
            )

    def push_speed(self, sample: SpeedSample) -> None:
        self._speed.push(sample.t_s, sample.speed_mps)

    # -- the frame step -----------------------------------------------------------------
    def push_frame(self, frame: CameraFrame) -> FrameResult:
        """Process one camera frame (its image None or garbage: no target)."""
        t = frame.t_s
        return self.push_vision(t, self.vision.process(t, frame.image, pitch_rad=self.pitch_rad))

    def frame_hold_s(self) -> float:
        """How long the run loop should hold the next camera frame back (`roadpreview.loop`;
        asked once per frame): the estimated camera-IMU offset plus ``[fusion]
        frame_hold_margin_s``, at most ``frame_hold_s``; ``frame_hold_s`` until an offset is
        known. It shrinks by at most `HOLD_STEP_S` per frame, so that a shorter hold never
        makes two frames due at once (a live loop would take that for falling behind)."""
        cfg = self.config.fusion
        r = self.last
        tau = r.time_offset if r is not None else math.nan
        if not math.isfinite(tau) or tau == 0.0:  # not estimated yet
            target = cfg.frame_hold_s
        else:
            target = min(cfg.frame_hold_s, max(0.0, tau) + cfg.frame_hold_margin_s)
        hold = self._hold_s
        self._hold_s = (
            target if target >= hold or math.isnan(hold) else max(target, hold - HOLD_STEP_S)
        )
        return self._hold_s

    @property
    def pitch_rad(self) -> float:
        """The camera's pitch relative to the road for the vision's horizon (0 before the
        first frame): the fused pitch of the last frame high-passed (``fusion.
        horizon_highpass_s``), since the slow part is the grade the lead shares."""
        return self._horizon.pitch_rad

    def push_vision(self, t: float, fv: FrameVision) -> FrameResult:
        """Steps 2-5 for a frame whose vision step is done (`push_frame` = vision + this).

        The evaluation runs one vision front end per recording and feeds its output to
        one pipeline per method, so that the methods differ only where they should."""
        cfg = self.config
        bg = fv.background
        pitch_reason = ""
        if bg.key_index != self._key_index:
            self._key_index = bg.key_index
            self.pitch.reset()  # the relative pitch starts again near zero
        n_bg = 0 if bg.x_cur is None else len(bg.x_cur)
        if fv.reason:
            pitch_reason = fv.reason
        elif not bg.quality.textured:
            pitch_reason = f"low texture: {bg.quality.reason}"
        elif n_bg < cfg.pitch.min_points:
            pitch_reason = f"{n_bg} background points < {cfg.pitch.min_points}"
        if not pitch_reason and bg.x_key is not None:
            est = self.pitch.estimate(bg.x_key, bg.x_cur)
            if est:
                self.fusion.push_visual(VisualPitch.from_estimate(bg.key_t, t, est))
            else:
                pitch_reason = est.reason
        if pitch_reason:
            self.fusion.push_vision_failure(t, pitch_reason)
        fused: FusedPitch = self.fusion.estimate(t)
        diverged = math.isfinite(fused.phi) and abs(fused.phi) > cfg.fusion.max_pitch_rad
        if diverged:  # no car pitches so far: the fusion has diverged; start it again
            self.pitch_divergences += 1
            log.error(
                "event=pitch_diverged t=%.3f phi_deg=%.1f count=%d: fusion reset, frame not"
                " compensated",
                t,
                math.degrees(fused.phi),
                self.pitch_divergences,
            )
            self.fusion.reset()
        phi = fused.phi if math.isfinite(fused.phi) and not diverged else 0.0
        self._horizon.update(t, phi)

        lead = fv.lead
        f = self.camera.fy
        comp = self.compensator.frame(
            t,
            (lead.y, lead.y_left, lead.y_right),
            phi,
            time_offset_s=fused.time_offset,
            distance_m=lead.distance_m,
            target_changed=lead.target_changed,
            valid=not diverged,
        )
        y_c = comp.y_c
        ego_speed = self._speed.speed_mps
        if lead.target_changed:
            self._lead.reset()
        lead_accel = self._lead.push(t, lead.distance_m, self._speed.accel)
        ego_v = self.ego_vertical.take(t)
        sample = TrajectorySample(
            t=t,
            y_c=y_c,
            y_c_left=comp.y_c_left,
            y_c_right=comp.y_c_right,
            lead_distance_m=lead.distance_m,
            lead_distance_std_m=lead.distance_std_m,
            mode=fused.mode,
            lead_accel_mps2=lead_accel,
            ego_speed_mps=ego_speed,
            valid=bool(lead) and math.isfinite(y_c),
            compensation_px=comp.total_px,
            focal_px=f,
            ego_accel_rms_mps2=ego_v.rms_mps2,
            ego_accel_peak_mps2=ego_v.peak_mps2,
        )
        events = self.detector.restart() if lead.target_changed else []
        events += self.detector.push(sample)
        batch = self.alert_builder.take(events)
        alerts = batch.confirmed
        self.alerts_sent += batch.new_ids
        if lead.target_changed:
            self.preview.restart()
        for a in batch.confirmed:  # (provisional alerts are too often false to draw)
            self.preview.add_alert(a)
        preview = self.preview.push(sample)
        road = self.roughness.push(
            t,
            ego_speed_mps=ego_speed,
            ego_accel_rms_mps2=ego_v.rms_mps2,
            ego_accel_samples=ego_v.n_samples,
            lead_y_c_px=y_c,
            lead_distance_m=lead.distance_m,
            focal_px=f,
            lead_valid=sample.valid,
        )
        for a in alerts:
            self.confirmer.add(a.alert_id, a.t_s, a.distance_m, a.side)
        confirmations = tuple(self.confirmer.push(t, ego_speed, ego_v.peak_mps2))
        df = self.detector.frame
        nan = math.nan
        result = FrameResult(
            t=t,
            index=fv.index,
            y=lead.y,
            y_left=lead.y_left,
            y_right=lead.y_right,
            y_c=y_c,
            phi=fused.phi,
            phi_std=fused.std,
            mode=fused.mode,
            bias=fused.bias,
            time_offset=fused.time_offset,
            s=df.s if df else nan,
            s_left=df.s_left if df else nan,
            s_right=df.s_right if df else nan,
            threshold_px=df.threshold_px if df else nan,
            suppressed=df.suppressed if df else SuppressionReason.NONE,
            lead_found=bool(lead),
            lead_distance_m=lead.distance_m,
            lead_box=lead.box,
            n_lead_points=lead.n_valid,
            n_background=n_bg,
            textured=bool(bg.quality.textured),
            vision_reason=fv.reason or lead.reason,
            pitch_reason=pitch_reason,
            target_changed=lead.target_changed,
            lead_accel_mps2=lead_accel,
            ego_speed_mps=ego_speed,
            heave_m=comp.heave_m,
            heave_px=comp.heave_px,
            score=df.score if df else nan,
            score_threshold=df.threshold if df else nan,
            score_t=df.t_score if df else nan,
            road_input_m=df.height_m if df else nan,
            background_m=df.background_m if df else nan,
            ego_accel_peak_mps2=ego_v.peak_mps2,
            road=road,
            sample=sample,
            events=tuple(events),
            alerts=alerts,
            provisional=batch.provisional,
            cancelled=batch.cancelled,
            confirmations=confirmations,
            preview=preview,
        )
        self.frames += 1
        self.last = result
        return result

    def finish(self) -> list[Alert]:
        """End of input: alerts for events still held by the non-maximum suppression."""
        batch = self.alert_builder.take(self.detector.flush())
        self.alerts_sent += batch.new_ids
        # (provisional alerts left unconfirmed end with the sender: STOPPED)
        return list(batch.confirmed)

    # -- status -------------------------------------------------------------------------
    def status(self) -> Status:
        """What ``RP_STATUS`` reports now."""
        r = self.last
        if r is None:
            return Status(mode=FusionMode.DEGRADED, frames_processed=0)
        quality = min(1.0, r.n_background / 200.0) if r.textured else 0.0
        return Status(
            mode=r.mode,
            pitch_rad=r.phi if math.isfinite(r.phi) else None,
            gyro_bias_rad_s=r.bias if math.isfinite(r.bias) else None,
            texture_quality=quality,
            time_offset_s=r.time_offset if math.isfinite(r.time_offset) else None,
            suppressed=r.suppressed,
            alerts_sent=self.alerts_sent,
            input_errors_total=self.input_errors,
            frames_processed=self.frames,
            road=r.road,
            precision=self.confirmer.precision() if self.confirmer.resolved else None,
            confirmed=self.confirmer.counts[Confirmation.CONFIRMED],
            not_felt=self.confirmer.counts[Confirmation.NOT_FELT],
        )
