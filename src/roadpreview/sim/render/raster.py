"""Paints a sorted draw list into the frame, painter's algorithm: projection, mip level,
homography warps of the textures and flat fills, with the vehicle-id mask, the inverse
depth and the lamps' emission alongside; and the sky on a plane at infinity."""

from __future__ import annotations

import math
from collections.abc import Sequence

import cv2
import numpy as np
from numpy.typing import NDArray

from roadpreview.camera import CameraModel
from roadpreview.sim.render.config import RenderConfig
from roadpreview.sim.render.geometry import clip_near
from roadpreview.sim.render.quads import DrawQuads
from roadpreview.sim.scene import SkySpec, Texture

F64 = NDArray[np.float64]
F32 = NDArray[np.float32]
U8 = NDArray[np.uint8]

#: the inverse depth written for "infinitely far" pixels (sky, beyond the draw distance)
INVZ_FAR = 1e-6


class Canvas:
    """The frame and its side buffers for one render."""

    def __init__(self, w: int, h: int, need_depth: bool, need_emission: bool) -> None:
        self.w, self.h = w, h
        self.img = np.empty((h, w, 3), np.uint8)
        self.vmask = np.zeros((h, w), np.int16)
        self.invz: F32 | None = np.full((h, w), INVZ_FAR, np.float32) if need_depth else None
        self.emission: U8 | None = np.zeros((h, w, 3), np.uint8) if need_emission else None
        self.vehicle_drawn = False


class Rasterizer:
    """Paints `DrawQuads` (sorted back to front) and the sky onto a `Canvas`.

    Parameters
    ----------
    camera
        Intrinsics and image size.
    cfg
        Near plane, level-of-detail limits, mip bias and the sky's resolution.
    """

    def __init__(self, camera: CameraModel, cfg: RenderConfig) -> None:
        self.camera = camera
        self.cfg = cfg
        self.K = camera.K
        u = np.arange(camera.width, dtype=np.float32)
        v = np.arange(camera.height, dtype=np.float32)
        #: pixel coordinate grids (float32), for the inverse-depth planes
        self.U, self.V = np.meshgrid(u, v)

    def paint_all(self, cv: Canvas, q: DrawQuads, textures: Sequence[Texture]) -> None:
        """Project all quads at once, then paint them in order (warps per bounding box)."""
        cfg = self.cfg
        cam = self.camera
        fx, fy, cx, cy = cam.fx, cam.fy, cam.cx, cam.cy
        n = q.pc.shape[0]
        if n == 0:
            return
        pc = q.pc
        z = pc[..., 2]
        near = cfg.near_m
        alive = z.max(axis=1) > near
        clipped = alive & (z.min(axis=1) < near)
        fast = alive & ~clipped
        zs = np.where(fast[:, None], z, 1.0)
        uv = np.stack([fx * pc[..., 0] / zs + cx, fy * pc[..., 1] / zs + cy], axis=-1)
        uv[~fast] = 0.0
        lo, hi = uv.min(axis=1), uv.max(axis=1)
        x0 = np.clip(np.floor(lo[:, 0]), 0, cv.w).astype(np.int64)
        y0 = np.clip(np.floor(lo[:, 1]), 0, cv.h).astype(np.int64)
        x1 = np.clip(np.ceil(hi[:, 0]) + 1, 0, cv.w).astype(np.int64)
        y1 = np.clip(np.ceil(hi[:, 1]) + 1, 0, cv.h).astype(np.int64)
        # sub-pixel flat details vanish under the lens blur: skip them
        tiny = (q.tex < 0) & ~q.emissive & ((hi - lo).max(axis=1) < 1.0)
        visible = clipped | (fast & (x1 > x0) & (y1 > y0) & ~tiny)
        # textures: mip level from the mean scale (px per texel) of the quad
        nlev = np.array([len(t.levels) for t in textures] + [1], np.int64)[q.tex]
        s0, t0, s1, t1 = q.rect.T
        area_tex = np.abs((s1 - s0) * (t1 - t0))
        area_px = 0.5 * np.abs(
            np.sum(
                uv[..., 0] * np.roll(uv[..., 1], -1, axis=1)
                - uv[..., 1] * np.roll(uv[..., 0], -1, axis=1),
                axis=1,
            )
        )
        with np.errstate(divide="ignore", invalid="ignore"):
            lvl = np.round(
                -0.5 * np.log2(np.maximum(area_px, 1e-12) / np.maximum(area_tex, 1e-12))
                + cfg.mip_bias
            )
        level = np.clip(np.nan_to_num(lvl), 0, nlev - 1).astype(np.int64)
        # thin or small planes (far kerbs, fences, poles) are filled with their mean colour
        edge = np.linalg.norm(uv - np.roll(uv, -1, axis=1), axis=2).max(axis=1)
        thin = area_px < cfg.lod_thin_px * edge
        small = ((hi - lo).max(axis=1) < cfg.lod_px) | thin
        flat = (q.tex < 0) | (small & fast)
        tex_mean = np.array([t.mean_bgr for t in textures] + [(0, 0, 0)], np.float64)[q.tex]
        fcol = np.where((q.tex >= 0)[:, None], tex_mean, q.colour) * q.shade[:, None]
        fcol = np.where(q.emissive[:, None], q.colour, np.minimum(fcol, 255.0)).astype(np.int64)
        Hm = self._homographies(pc, q.rect, level, x0, y0)
        pts = np.round((uv - np.stack([x0, y0], axis=1)[:, None, :]) * 16.0).astype(np.int32)
        depth = self._depth_planes(pc) if cv.invz is not None else None

        order = np.nonzero(visible)[0].tolist()
        xl, yl, xh, yh = x0.tolist(), y0.tolist(), x1.tolist(), y1.tolist()
        texl, lvll, flatl, vidl, shadel = (
            q.tex.tolist(),
            level.tolist(),
            flat.tolist(),
            q.vid.tolist(),
            q.shade.tolist(),
        )
        cl, eml = fcol.tolist(), q.emissive.tolist()
        clipl = clipped.tolist()
        for i in order:
            vid = vidl[i]
            if vid:
                cv.vehicle_drawn = True
            if clipl[i]:
                self._paint_clipped(cv, q, i, textures, depth)
                continue
            self._paint(
                cv,
                xl[i],
                yl[i],
                xh[i],
                yh[i],
                pts[i],
                None if flatl[i] else textures[texl[i]],
                lvll[i],
                Hm[i],
                tuple(cl[i]),
                shadel[i],
                vid,
                None if depth is None else depth[i],
                eml[i],
            )

    def _homographies(
        self,
        pc: F64,
        rect: F64,
        level: NDArray[np.int64],
        x0: NDArray[np.int64],
        y0: NDArray[np.int64],
    ) -> F64:
        """Texture (level-L pixel centres) -> image ROI homographies of all quads.

        Level-L pixel c covers level-0 texel edges [c 2^L, (c + 1) 2^L): its centre
        is the edge coordinate (c + 0.5) 2^L, mapped linearly onto the quad.
        """
        s0, t0, s1, t1 = rect.T
        k = np.exp2(level.astype(np.float64))
        with np.errstate(divide="ignore", invalid="ignore"):
            a = (pc[:, 1] - pc[:, 0]) / np.where(s1 != s0, s1 - s0, 1.0)[:, None]
            b = (pc[:, 3] - pc[:, 0]) / np.where(t1 != t0, t1 - t0, 1.0)[:, None]
        M = np.empty((pc.shape[0], 3, 3))
        M[:, :, 0] = k[:, None] * a
        M[:, :, 1] = k[:, None] * b
        M[:, :, 2] = pc[:, 0] + (0.5 * k - s0)[:, None] * a + (0.5 * k - t0)[:, None] * b
        Hm: F64 = np.einsum("ij,njk->nik", self.K, M)
        Hm[:, 0, :] -= x0[:, None] * Hm[:, 2, :]
        Hm[:, 1, :] -= y0[:, None] * Hm[:, 2, :]
        return Hm

    def _depth_planes(self, pc: F64) -> F64:
        """(N, 3) coefficients (a, b, c) with 1/z = a u + b v + c on each quad's plane."""
        cam = self.camera
        nrm = np.cross(pc[:, 1] - pc[:, 0], pc[:, 3] - pc[:, 0])
        c = np.einsum("ij,ij->i", nrm, pc[:, 0])
        c = np.where(np.abs(c) < 1e-12, np.inf, c)
        a = nrm[:, 0] / cam.fx / c
        b = nrm[:, 1] / cam.fy / c
        c0 = (nrm[:, 2] - nrm[:, 0] * cam.cx / cam.fx - nrm[:, 1] * cam.cy / cam.fy) / c
        return np.stack([a, b, c0], axis=1)

    def _paint_clipped(
        self, cv: Canvas, q: DrawQuads, i: int, textures: Sequence[Texture], depth: F64 | None
    ) -> None:
        """A quad crossing the near plane: clip in 3-D first, then paint as usual."""
        cam = self.camera
        pc = q.pc[i]
        poly = clip_near(pc, self.cfg.near_m)
        if poly.shape[0] < 3:
            return
        uv = np.stack(
            [cam.fx * poly[:, 0] / poly[:, 2] + cam.cx, cam.fy * poly[:, 1] / poly[:, 2] + cam.cy],
            axis=1,
        )
        lo, hi = uv.min(axis=0), uv.max(axis=0)
        x0, y0 = max(0, math.floor(lo[0])), max(0, math.floor(lo[1]))
        x1, y1 = min(cv.w, math.ceil(hi[0]) + 1), min(cv.h, math.ceil(hi[1]) + 1)
        if x1 <= x0 or y1 <= y0:
            return
        tid = int(q.tex[i])
        tex = textures[tid] if tid >= 0 else None
        level = 0
        if tex is not None:
            s0, t0, s1, t1 = q.rect[i]
            e1, e2 = pc[1] - pc[0], pc[3] - pc[0]
            rel = poly - pc[0]
            ta = rel @ e1 / float(e1 @ e1) * (s1 - s0)
            tb = rel @ e2 / float(e2 @ e2) * (t1 - t0)
            a_tex = 0.5 * abs(float(np.dot(ta, np.roll(tb, -1)) - np.dot(tb, np.roll(ta, -1))))
            a_px = 0.5 * abs(
                float(
                    np.dot(uv[:, 0], np.roll(uv[:, 1], -1))
                    - np.dot(uv[:, 1], np.roll(uv[:, 0], -1))
                )
            )
            if a_tex > 0 and a_px > 0:
                level = int(
                    np.clip(
                        round(-0.5 * math.log2(a_px / a_tex) + self.cfg.mip_bias),
                        0,
                        len(tex.levels) - 1,
                    )
                )
        Hm = self._homographies(
            pc[None], q.rect[i : i + 1], np.array([level]), np.array([x0]), np.array([y0])
        )[0]
        pts = np.round((uv - (x0, y0)) * 16.0).astype(np.int32)
        if q.emissive[i]:
            colour = tuple(int(c) for c in q.colour[i])
        else:
            base = tex.mean_bgr if tex is not None else q.colour[i]
            colour = tuple(int(min(255.0, float(c) * float(q.shade[i]))) for c in base)
        self._paint(
            cv,
            x0,
            y0,
            x1,
            y1,
            pts,
            tex,
            level,
            Hm,
            colour,
            float(q.shade[i]),
            int(q.vid[i]),
            None if depth is None else depth[i],
            bool(q.emissive[i]),
        )

    def _paint(
        self,
        cv: Canvas,
        x0: int,
        y0: int,
        x1: int,
        y1: int,
        pts: NDArray[np.int32],
        tex: Texture | None,
        level: int,
        Hm: F64,
        colour: tuple[int, ...],
        shade: float,
        vid: int,
        depth: F64 | None,
        emissive: bool,
    ) -> None:
        """Paint one projected polygon: flat fill, or the texture warped over its box."""
        roi = cv.img[y0:y1, x0:x1]
        bw, bh = x1 - x0, y1 - y0
        if emissive:
            cv2.fillConvexPoly(roi, pts, colour, shift=4)
            if cv.emission is not None:
                cv2.fillConvexPoly(cv.emission[y0:y1, x0:x1], pts, colour, shift=4)
            return
        mask: U8 | None = None
        if tex is None:
            cv2.fillConvexPoly(roi, pts, colour, shift=4)
            if depth is not None or cv.emission is not None:
                mask = np.zeros((bh, bw), np.uint8)
                cv2.fillConvexPoly(mask, pts, 255, shift=4)
        else:
            warped = cv2.warpPerspective(
                tex.levels[level],
                Hm,
                (bw, bh),
                flags=cv2.INTER_LINEAR,
                borderMode=cv2.BORDER_REPLICATE,
            )
            mask = np.zeros((bh, bw), np.uint8)
            cv2.fillConvexPoly(mask, pts, 255, shift=4)
            if tex.has_alpha:
                _, alpha = cv2.threshold(warped[..., 3], 127, 255, cv2.THRESH_BINARY)
                mask = np.asarray(cv2.bitwise_and(mask, alpha), np.uint8)
                warped = cv2.cvtColor(warped, cv2.COLOR_BGRA2BGR)
            if shade != 1.0:
                warped = cv2.convertScaleAbs(warped, alpha=shade)
            cv2.copyTo(warped, mask, roi)
        vm = cv.vmask[y0:y1, x0:x1]
        if vid:
            cv2.fillConvexPoly(vm, pts, vid, shift=4)
        elif cv.vehicle_drawn:  # occludes vehicles drawn before
            if mask is None:
                cv2.fillConvexPoly(vm, pts, 0, shift=4)
            else:
                cv2.subtract(vm, vm, dst=vm, mask=mask)
        if mask is None:
            return
        if cv.emission is not None:
            em = cv.emission[y0:y1, x0:x1]
            cv2.subtract(em, em, dst=em, mask=mask)
        if depth is not None and cv.invz is not None:
            plane = cv2.addWeighted(
                self.U[y0:y1, x0:x1],
                float(depth[0]),
                self.V[y0:y1, x0:x1],
                float(depth[1]),
                float(depth[2]),
            )
            cv2.copyTo(plane, mask, cv.invz[y0:y1, x0:x1])

    def draw_sky(self, cv: Canvas, R: F64, sky: SkySpec, tex: Texture) -> None:
        """The sky plane at infinity (rotation only), warped at reduced resolution."""
        cam = self.camera
        n_c = R @ np.array([0.0, 0.0, 1.0])
        lvec = np.linalg.inv(self.K).T @ n_c
        if abs(lvec[1]) < 1e-9:
            v_end = cv.h
        else:
            vs = [-(lvec[0] * u + lvec[2]) / lvec[1] for u in (0.0, cv.w - 1.0)]
            v_end = int(min(cv.h, max(0.0, max(vs) + 0.12 * cv.h)))
        if v_end <= 0:
            return
        m = self.cfg.sky_downsample
        ws, hs = math.ceil(cv.w / m), math.ceil(v_end / m)
        # small pixel j is centred on full pixel (j + 0.5) m - 0.5, as cv2.resize maps
        Ks = np.array(
            [
                [cam.fx / m, 0.0, (cam.cx + 0.5) / m - 0.5],
                [0.0, cam.fy / m, (cam.cy + 0.5) / m - 0.5],
                [0.0, 0.0, 1.0],
            ]
        )
        step = sky.step
        M = np.array(
            [
                [0.0, 0.0, 1.0],
                [-step, 0.0, sky.tan_az_max - 0.5 * step],
                [0.0, -step, sky.tan_el_max - 0.5 * step],
            ]
        )
        small = cv2.warpPerspective(
            tex.levels[0],
            Ks @ R @ M,
            (ws, hs),
            flags=cv2.INTER_LINEAR,
            borderMode=cv2.BORDER_REPLICATE,
        )
        big = (
            small if m == 1 else cv2.resize(small, (ws * m, hs * m), interpolation=cv2.INTER_LINEAR)
        )
        cv.img[:v_end] = big[:v_end, : cv.w]
