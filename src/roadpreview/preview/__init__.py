"""Road-profile preview (``RP_PREVIEW``): the road ahead along the ego's path, where the lead's
wheels have been, by inverting the lead's vertical response through the nominal car.

The lead's compensated image row is y_c(t) = -(f / d) z_face(t) + a + b t (v down, so a
rising lead lowers y_c; the offset and slope absorb slow drift). Its rear face moves as
the two-axle response of the nominal car (`roadpreview.anomaly.response`) to the road
w(t) under its front wheel: z_face = (1 + ρ) q(t - τ) - ρ q(t), q the quarter car's body
response, τ = wheelbase / v_lead. Every ``period_s`` `ProfileEstimator`:

1. puts the last frames (up to ``history_s``: as much as reaches back to the road now
   under the ego's front axle, plus half a second) on a regular frame grid; y_c and y_c,L -
   y_c,R become metres by -d / f (heave and roll channels);
2. takes the road's increments u_j between grid times as unknowns (w piecewise linear),
   including ``settle_s`` + τ before the history whose response is still in its first
   frames; the discrete operator (the nominal car's response to one ramp, `face_operator`,
   cached per grid step, τ and size) has the drift's span projected out;
3. solves the Gaussian MAP with white tracking noise and an ISO 8608 prior: G_d(n) =
   G_d(n0) (n / n0)^-2 is a random walk in space, increments of variance
   2 π² G_d(n0) n0² v_lead dt per grid step (independent increments: a diagonal prior, so
   one eigen-decomposition of the cached normal matrix serves every solve); the posterior
   mean and the diagonal of its covariance give height and std;
4. maps grid time t_k to the path ahead of the ego's front axle now, x_k = d(t_k) +
   overhang + wheelbase - camera_to_front_axle - (the ego's distance since t_k), and
   averages the piecewise-linear road over 0.5 m bins up to the lead's rear axle;
5. removes the least-squares line over the valid bins: the level and the grade are in the
   drift's span and cannot be observed; heights are relative to that local plane.

Left / right tracks: heave ± roll / 2 (the detector's convention). `roadpreview.eval.road_truth`
compares previews with the simulator's road. ``docs/method.md``, "The road-profile preview".
"""

from __future__ import annotations

from roadpreview.preview.config import PreviewConfig
from roadpreview.preview.profile import FaceOperator, ProfileEstimator, face_operator
from roadpreview.types import RoadPreview

__all__ = [
    "FaceOperator",
    "PreviewConfig",
    "ProfileEstimator",
    "RoadPreview",
    "face_operator",
]
