"""A lead finder running a user's ONNX detector or instance-segmentation model (onnxruntime).

What the model expects and returns comes from a small *model description*,
not from code: a TOML file passed explicitly or lying next to the model
(``model.onnx`` -> ``model.toml``), else the model's own metadata (Ultralytics
exports carry ``names``, ``imgsz`` and ``task``). The description gives the
input (name, NCHW/NHWC, size, colour order, scale/mean/std, letterbox at the
centre or top-left with its pad value), the output format and the class names,
and which classes are vehicles. Supported outputs:

* ``yolox``: raw YOLOX head ``[1, N, 5 + nc]`` on grids of strides 8/16/32,
  rows ``[dx, dy, log w, log h, objectness, class scores]``;
* ``yolov8``: Ultralytics YOLOv8/YOLO11 detection ``[1, 4 + nc, N]`` (centre,
  size, class scores);
* ``yolov8-seg``: the same with 32 mask coefficients per anchor and a second
  output of mask prototypes ``[1, 32, H/4, W/4]``.

Decoding is vectorised over all anchors; boxes are filtered by score and class
and suppressed by NMS (OpenCV's). A model whose outputs do not match its
description raises `InputDataError` naming the tensor and both shapes.
"""

from __future__ import annotations

import ast
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from roadpreview._tomlio import load_toml
from roadpreview.camera import CameraModel
from roadpreview.configtools import check_ranges, from_mapping, param
from roadpreview.errors import ConfigError, InputDataError, MissingDependencyError
from roadpreview.vision.base import F32, U8, Detection, FrameContext

#: the 80 COCO classes in the order YOLOX and Ultralytics models use
COCO_CLASSES: tuple[str, ...] = (
    "person",
    "bicycle",
    "car",
    "motorcycle",
    "airplane",
    "bus",
    "train",
    "truck",
    "boat",
    "traffic_light",
    "fire_hydrant",
    "stop_sign",
    "parking_meter",
    "bench",
    "bird",
    "cat",
    "dog",
    "horse",
    "sheep",
    "cow",
    "elephant",
    "bear",
    "zebra",
    "giraffe",
    "backpack",
    "umbrella",
    "handbag",
    "tie",
    "suitcase",
    "frisbee",
    "skis",
    "snowboard",
    "sports_ball",
    "kite",
    "baseball_bat",
    "baseball_glove",
    "skateboard",
    "surfboard",
    "tennis_racket",
    "bottle",
    "wine_glass",
    "cup",
    "fork",
    "knife",
    "spoon",
    "bowl",
    "banana",
    "apple",
    "sandwich",
    "orange",
    "broccoli",
    "carrot",
    "hot_dog",
    "pizza",
    "donut",
    "cake",
    "chair",
    "couch",
    "potted_plant",
    "bed",
    "dining_table",
    "toilet",
    "tv",
    "laptop",
    "mouse",
    "remote",
    "keyboard",
    "cell_phone",
    "microwave",
    "oven",
    "toaster",
    "sink",
    "refrigerator",
    "book",
    "clock",
    "vase",
    "scissors",
    "teddy_bear",
    "hair_drier",
    "toothbrush",
)

FORMATS = ("yolox", "yolov8", "yolov8-seg")


@dataclass(frozen=True)
class ModelDescription:
    """How to feed a detector and read its outputs (one TOML file per model)."""

    format: str = param("yolov8", choices=FORMATS, help="output layout, see the module doc")
    input_name: str = param("", help="input tensor; '' = the model's first input")
    layout: str = param("NCHW", choices=("NCHW", "NHWC"), help="input tensor layout")
    input_width: int = param(0, ge=0, unit="px", help="0 = from the model's input shape")
    input_height: int = param(0, ge=0, unit="px", help="0 = from the model's input shape")
    color: str = param("RGB", choices=("RGB", "BGR"), help="channel order the model expects")
    scale: float = param(
        1.0 / 255.0, gt=0.0, help="pixel values 0-255 are multiplied by this (1/255: Ultralytics)"
    )
    mean: tuple[float, float, float] = param((0.0, 0.0, 0.0), help="subtracted after scaling")
    std: tuple[float, float, float] = param((1.0, 1.0, 1.0), help="divided by after the mean")
    letterbox: str = param(
        "center",
        choices=("center", "top-left", "stretch"),
        help="keep the aspect ratio, image centred (Ultralytics) or top-left (YOLOX), or stretch",
    )
    pad_value: float = param(114.0, ge=0.0, le=255.0, help="letterbox fill (0-255 scale)")
    output_name: str = param("", help="detections output; '' = the model's first output")
    mask_output_name: str = param("", help="yolov8-seg prototypes; '' = the second output")
    strides: tuple[int, ...] = param((8, 16, 32), help="yolox grid strides")
    num_mask_coeffs: int = param(32, ge=1, help="yolov8-seg mask coefficients per box")
    class_names: tuple[str, ...] = param(COCO_CLASSES, help="class index -> name")
    vehicle_classes: tuple[str, ...] = param(
        ("car", "bus", "truck"), help="classes that can be the lead vehicle"
    )

    def validate(self, where: str = "model") -> None:
        check_ranges(self, where)
        if not self.class_names:
            raise ConfigError(f"{where}.class_names: empty")
        missing = [c for c in self.vehicle_classes if c not in self.class_names]
        if missing:
            raise ConfigError(
                f"{where}.vehicle_classes {missing} are not among the model's class_names"
            )
        if any(s <= 0 for s in self.strides):
            raise ConfigError(f"{where}.strides = {list(self.strides)}: must be positive")
        if any(s <= 0 for s in self.std):
            raise ConfigError(f"{where}.std = {list(self.std)}: must be positive")

    @property
    def vehicle_ids(self) -> NDArray[np.int64]:
        return np.array([self.class_names.index(c) for c in self.vehicle_classes], np.int64)

    @classmethod
    def load(cls, path: str | Path) -> ModelDescription:
        """Read a description from TOML (a ``[model]`` table or the keys at top level)."""
        data: Any = load_toml(path)
        table = data.get("model", data)
        return from_mapping(cls, table, source=str(path), where="model")


def description_from_metadata(meta: dict[str, str]) -> ModelDescription | None:
    """A description from ONNX metadata (Ultralytics: ``names``, ``imgsz``, ``task``)."""
    if "names" not in meta:
        return None
    try:
        names_raw = ast.literal_eval(meta["names"])
        if isinstance(names_raw, dict):
            names = tuple(str(names_raw[k]) for k in sorted(names_raw))
        else:
            names = tuple(str(v) for v in names_raw)
        size = ast.literal_eval(meta.get("imgsz", "[0, 0]"))
    except (ValueError, SyntaxError) as exc:
        raise InputDataError(f"ONNX metadata 'names'/'imgsz' unreadable: {exc}") from None
    task = meta.get("task", "detect")
    fmt = "yolov8-seg" if task == "segment" else "yolov8"
    vehicles = tuple(c for c in ("car", "bus", "truck") if c in names)
    h, w = (int(size[0]), int(size[1])) if isinstance(size, list | tuple) else (0, 0)
    desc = ModelDescription(
        format=fmt, input_width=w, input_height=h, class_names=names, vehicle_classes=vehicles
    )
    desc.validate("metadata")
    return desc


# -- pre-processing ------------------------------------------------------------------------
@dataclass(frozen=True)
class Letterbox:
    """How a frame was put into the model's input: input = frame * (sx, sy) + (px, py)."""

    sx: float
    sy: float
    px: float
    py: float

    def to_frame(self, boxes: F32) -> F32:
        """(N, 4) xyxy boxes in input pixels back to frame pixels."""
        out = boxes.astype(np.float32).copy()
        out[:, 0::2] = (out[:, 0::2] - self.px) / self.sx
        out[:, 1::2] = (out[:, 1::2] - self.py) / self.sy
        return out


def preprocess(
    frame_bgr: U8, desc: ModelDescription, width: int, height: int
) -> tuple[F32, Letterbox]:
    """The model's input tensor (batch of one) and the letterbox transform."""
    h, w = frame_bgr.shape[:2]
    if desc.letterbox == "stretch":
        sx, sy = width / w, height / h
        img = cv2.resize(frame_bgr, (width, height), interpolation=cv2.INTER_LINEAR)
        lb = Letterbox(sx, sy, 0.0, 0.0)
    else:
        r = min(width / w, height / h)
        nw, nh = max(1, round(w * r)), max(1, round(h * r))
        resized = cv2.resize(frame_bgr, (nw, nh), interpolation=cv2.INTER_LINEAR)
        if desc.letterbox == "center":
            px, py = (width - nw) // 2, (height - nh) // 2
        else:
            px, py = 0, 0
        img = np.full((height, width, 3), desc.pad_value, np.uint8)
        img[py : py + nh, px : px + nw] = resized
        lb = Letterbox(nw / w, nh / h, float(px), float(py))
    if desc.color == "RGB":
        img = cv2.cvtColor(img, cv2.COLOR_BGR2RGB)
    x = img.astype(np.float32) * np.float32(desc.scale)
    mean, std = np.array(desc.mean, np.float32), np.array(desc.std, np.float32)
    if np.any(mean != 0.0) or np.any(std != 1.0):
        x = (x - mean) / std
    if desc.layout == "NCHW":
        x = x.transpose(2, 0, 1)
    return np.ascontiguousarray(x[None], np.float32), lb


# -- decoders (vectorised over all anchors) ------------------------------------------------
def yolox_grids(width: int, height: int, strides: Sequence[int]) -> tuple[F32, F32]:
    """(N, 2) grid cell offsets and (N,) strides of a YOLOX head, rows in YOLOX's order."""
    grids, st = [], []
    for s in strides:
        gx, gy = np.meshgrid(np.arange(width // s), np.arange(height // s))
        grids.append(np.stack([gx.ravel(), gy.ravel()], axis=1))
        st.append(np.full(gx.size, s))
    return np.concatenate(grids).astype(np.float32), np.concatenate(st).astype(np.float32)


@dataclass(frozen=True)
class Decoded:
    """Decoded candidate boxes before NMS (input pixels)."""

    boxes: F32  # (M, 4) x0, y0, x1, y1
    scores: F32  # (M,)
    classes: NDArray[np.int64]  # (M,)
    coeffs: F32 | None = None  # (M, nm) mask coefficients (yolov8-seg)


def decode_yolox(
    raw: F32, grids: F32, strides: F32, class_ids: NDArray[np.int64], threshold: float
) -> Decoded:
    """Raw YOLOX rows ``(N, 5 + nc)`` to boxes: xy = (d + cell) s, wh = exp(l) s,
    score = objectness x class score, over the ``class_ids`` columns only."""
    obj = raw[:, 4]
    cls = raw[:, 5 + class_ids]
    j = np.argmax(cls, axis=1)
    score = obj * cls[np.arange(cls.shape[0]), j]
    keep = score >= threshold
    r = raw[keep]
    s = strides[keep, None]
    xy = (r[:, :2] + grids[keep]) * s
    wh = np.exp(np.minimum(r[:, 2:4], 20.0)) * s
    boxes = np.concatenate([xy - wh / 2, xy + wh / 2], axis=1).astype(np.float32)
    return Decoded(boxes, score[keep].astype(np.float32), class_ids[j[keep]])


def decode_yolov8(
    raw: F32, n_classes: int, class_ids: NDArray[np.int64], threshold: float, n_coeffs: int = 0
) -> Decoded:
    """Ultralytics ``(4 + nc [+ nm], N)`` to boxes (centre/size, class scores, no objectness)."""
    a = raw.T  # (N, 4 + nc [+ nm])
    cls = a[:, 4 + class_ids]
    j = np.argmax(cls, axis=1)
    score = cls[np.arange(cls.shape[0]), j]
    keep = score >= threshold
    r = a[keep]
    xy, wh = r[:, :2], r[:, 2:4]
    boxes = np.concatenate([xy - wh / 2, xy + wh / 2], axis=1).astype(np.float32)
    coeffs = r[:, 4 + n_classes : 4 + n_classes + n_coeffs].astype(np.float32) if n_coeffs else None
    return Decoded(boxes, score[keep].astype(np.float32), class_ids[j[keep]], coeffs)


def nms(dec: Decoded, iou: float, max_det: int) -> NDArray[np.int64]:
    """Indices kept by class-agnostic NMS (a car also scored as a truck is one vehicle)."""
    if dec.boxes.shape[0] == 0:
        return np.empty(0, np.int64)
    b = dec.boxes
    xywh = np.stack([b[:, 0], b[:, 1], b[:, 2] - b[:, 0], b[:, 3] - b[:, 1]], axis=1)
    keep = cv2.dnn.NMSBoxes(xywh.tolist(), dec.scores.tolist(), 0.0, iou)
    idx = np.asarray(keep, np.int64).reshape(-1)
    return idx[:max_det]


def masks_from_protos(
    coeffs: F32, protos: F32, boxes_in: F32, input_size: tuple[int, int]
) -> NDArray[np.bool_]:
    """Instance masks at prototype resolution: sigmoid(coeffs @ protos) > 0.5 inside the box.

    ``protos`` is (nm, mh, mw); ``boxes_in`` are in input pixels of ``input_size`` (w, h).
    """
    nm, mh, mw = protos.shape
    logits = (coeffs @ protos.reshape(nm, -1)).reshape(-1, mh, mw)
    w, h = input_size
    sx, sy = mw / w, mh / h
    xs = (np.arange(mw) + 0.5)[None, None, :]
    ys = (np.arange(mh) + 0.5)[None, :, None]
    b = boxes_in
    inside_box = (
        (xs >= b[:, 0, None, None] * sx)
        & (xs <= b[:, 2, None, None] * sx)
        & (ys >= b[:, 1, None, None] * sy)
        & (ys <= b[:, 3, None, None] * sy)
    )
    return np.asarray((logits > 0.0) & inside_box)  # sigmoid > 0.5 <=> logit > 0


# -- shape checks ---------------------------------------------------------------------------
def _dims(shape: Sequence[Any]) -> list[int | None]:
    return [d if isinstance(d, int) and d > 0 else None for d in shape]


def _fmt(shape: Sequence[int | None]) -> str:
    return "[" + ", ".join("?" if d is None else str(d) for d in shape) + "]"


def expected_outputs(
    desc: ModelDescription, width: int, height: int
) -> list[tuple[str, list[int | None]]]:
    """(role, expected shape) of the outputs the description promises (None = any)."""
    nc = len(desc.class_names)
    n_anchors = sum((width // s) * (height // s) for s in desc.strides)
    if desc.format == "yolox":
        return [("detections", [1, n_anchors, 5 + nc])]
    if desc.format == "yolov8":
        return [("detections", [1, 4 + nc, n_anchors])]
    nm = desc.num_mask_coeffs
    return [
        ("detections", [1, 4 + nc + nm, n_anchors]),
        ("mask prototypes", [1, nm, height // 4, width // 4]),
    ]


def check_shape(
    tensor: str, actual: Sequence[Any], expected: Sequence[int | None], where: str, what: str
) -> None:
    """Raise `InputDataError` naming ``tensor`` if ``actual`` cannot be ``expected``."""
    act = _dims(actual)
    ok = len(act) == len(expected) and all(
        a is None or e is None or a == e for a, e in zip(act, expected, strict=True)
    )
    if not ok:
        raise InputDataError(
            f"{where}: output tensor {tensor!r} has shape {_fmt(act)}; the model description "
            f"({what}) expects {_fmt(expected)}"
        )


def validate_session(
    session: Any, desc: ModelDescription, where: str
) -> tuple[str, int, int, list[str]]:
    """Check a session's input and outputs against ``desc``.

    ``session`` is anything with onnxruntime's ``get_inputs()``/``get_outputs()``
    (items with ``.name`` and ``.shape``). Returns (input name, width, height,
    output names in the roles of `expected_outputs`).
    """
    inputs = list(session.get_inputs())
    outputs = list(session.get_outputs())
    if not inputs:
        raise InputDataError(f"{where}: the model has no input")
    names = [i.name for i in inputs]
    in_name = desc.input_name or names[0]
    if in_name not in names:
        raise InputDataError(f"{where}: no input tensor {in_name!r} (inputs: {names})")
    shape = _dims(inputs[names.index(in_name)].shape)
    if len(shape) != 4:
        raise InputDataError(
            f"{where}: input tensor {in_name!r} has shape {_fmt(shape)}; expected a 4-D "
            f"{desc.layout} image batch"
        )
    hw = (shape[2], shape[3]) if desc.layout == "NCHW" else (shape[1], shape[2])
    ch = shape[1] if desc.layout == "NCHW" else shape[3]
    if ch is not None and ch != 3:
        raise InputDataError(
            f"{where}: input tensor {in_name!r} has shape {_fmt(shape)}: {ch} channels where "
            f"the description's layout {desc.layout} expects 3"
        )
    height = desc.input_height or hw[0] or 0
    width = desc.input_width or hw[1] or 0
    if width <= 0 or height <= 0:
        raise InputDataError(
            f"{where}: input tensor {in_name!r} has a dynamic size {_fmt(shape)}; set "
            "input_width and input_height in the model description"
        )
    out_names = [o.name for o in outputs]
    wanted = [desc.output_name or (out_names[0] if out_names else "")]
    if desc.format == "yolov8-seg":
        wanted.append(desc.mask_output_name or (out_names[1] if len(out_names) > 1 else ""))
    what = f"format {desc.format!r}, {len(desc.class_names)} classes, input {width}x{height}"
    for (role, exp), name in zip(expected_outputs(desc, width, height), wanted, strict=True):
        if name not in out_names:
            raise InputDataError(
                f"{where}: no output tensor for the {role} ({name!r}); the model's outputs are "
                f"{out_names}; the description ({what}) expects a {role} tensor of shape "
                f"{_fmt(exp)}"
            )
        check_shape(name, outputs[out_names.index(name)].shape, exp, where, what)
    return in_name, width, height, wanted


# -- the finder -----------------------------------------------------------------------------
@dataclass(frozen=True)
class OnnxFinderConfig:
    """Settings of `OnnxLeadFinder`."""

    model_path: str = param("", help="the .onnx file (required)")
    description: str = param(
        "", help="model description TOML; '' = <model>.toml next to the model, else metadata"
    )
    score_threshold: float = param(0.3, ge=0.0, le=1.0, help="lower scores are dropped")
    nms_iou: float = param(0.45, gt=0.0, le=1.0, help="NMS overlap")
    max_detections: int = param(50, ge=1, help="at most this many vehicles per frame")
    threads: int = param(1, ge=0, help="onnxruntime intra-op threads (0 = its default)")
    description_overrides: dict[str, Any] = field(default_factory=dict)

    def validate(self, where: str = "OnnxFinderConfig") -> None:
        check_ranges(self, where)
        if not self.model_path:
            raise ConfigError(f"{where}.model_path: the onnx finder needs a model file")


class OnnxLeadFinder:
    """Runs a detector and returns its vehicles as `Detection` boxes (full-frame pixels)."""

    name = "onnx"

    def __init__(self, camera: CameraModel, config: OnnxFinderConfig | None = None) -> None:
        try:
            import onnxruntime as ort
        except ImportError:
            raise MissingDependencyError(
                "the 'onnx' lead finder needs onnxruntime: pip install onnxruntime "
                "(or use the built-in 'motion' finder)"
            ) from None
        self.camera = camera
        self.config = config or OnnxFinderConfig()
        self.config.validate()
        path = Path(self.config.model_path)
        if not path.is_file():
            raise ConfigError(f"model_path = {str(path)!r}: file not found")
        opts = ort.SessionOptions()
        if self.config.threads:
            opts.intra_op_num_threads = self.config.threads
        try:
            self.session = ort.InferenceSession(
                str(path), sess_options=opts, providers=["CPUExecutionProvider"]
            )
        except Exception as exc:  # onnxruntime raises its own exception types
            raise InputDataError(f"{path}: onnxruntime cannot load the model: {exc}") from None
        self.description = self._description(path)
        self.input_name, self.width, self.height, self.output_names = validate_session(
            self.session, self.description, str(path)
        )
        self._where = str(path)
        if self.description.format == "yolox":
            self._grids, self._strides = yolox_grids(
                self.width, self.height, self.description.strides
            )
        self.last_reason = ""

    def _description(self, path: Path) -> ModelDescription:
        cfg = self.config
        if cfg.description:
            desc = ModelDescription.load(cfg.description)
        elif path.with_suffix(".toml").is_file():
            desc = ModelDescription.load(path.with_suffix(".toml"))
        else:
            meta = dict(self.session.get_modelmeta().custom_metadata_map)
            found = description_from_metadata(meta)
            if found is None:
                raise ConfigError(
                    f"{path}: no model description: pass one (description = '...toml'), put "
                    f"{path.with_suffix('.toml').name} next to the model, or export with metadata"
                )
            desc = found
        if cfg.description_overrides:
            from roadpreview.configtools import to_mapping

            merged = {**to_mapping(desc), **cfg.description_overrides}
            desc = from_mapping(ModelDescription, merged, where="model")
        desc.validate("model")
        return desc

    def reset(self) -> None:
        return None

    def observe(self, frame_bgr: U8, context: FrameContext | None = None) -> None:
        return None

    def find(self, frame_bgr: U8, context: FrameContext | None = None) -> list[Detection]:
        desc = self.description
        cfg = self.config
        x, lb = preprocess(frame_bgr, desc, self.width, self.height)
        outs = self.session.run(self.output_names, {self.input_name: x})
        raw = np.asarray(outs[0], np.float32)
        what = f"format {desc.format!r}, {len(desc.class_names)} classes"
        exp = expected_outputs(desc, self.width, self.height)
        check_shape(self.output_names[0], raw.shape, exp[0][1], self._where, what)
        ids = desc.vehicle_ids
        nc = len(desc.class_names)
        if desc.format == "yolox":
            dec = decode_yolox(raw[0], self._grids, self._strides, ids, cfg.score_threshold)
        else:
            nm = desc.num_mask_coeffs if desc.format == "yolov8-seg" else 0
            dec = decode_yolov8(raw[0], nc, ids, cfg.score_threshold, nm)
        keep = nms(dec, cfg.nms_iou, cfg.max_detections)
        if keep.size == 0:
            self.last_reason = "no vehicle above the score threshold"
            return []
        boxes_in = dec.boxes[keep]
        boxes = lb.to_frame(boxes_in)
        masks: NDArray[np.bool_] | None = None
        if desc.format == "yolov8-seg" and dec.coeffs is not None:
            protos = np.asarray(outs[1], np.float32)
            check_shape(self.output_names[1], protos.shape, exp[1][1], self._where, what)
            small = masks_from_protos(
                dec.coeffs[keep], protos[0], boxes_in, (self.width, self.height)
            )
            masks = self._masks_to_frame(small, lb, frame_bgr.shape[1], frame_bgr.shape[0])
        h, w = frame_bgr.shape[:2]
        out: list[Detection] = []
        for i in range(keep.size):  # a handful of detections
            b = boxes[i]
            box = (
                float(np.clip(b[0], 0, w - 1)),
                float(np.clip(b[1], 0, h - 1)),
                float(np.clip(b[2], 0, w - 1)),
                float(np.clip(b[3], 0, h - 1)),
            )
            if box[2] - box[0] < 1 or box[3] - box[1] < 1:
                continue
            name = desc.class_names[int(dec.classes[keep[i]])]
            sigma = max(2.0, 0.03 * (box[2] - box[0]))
            out.append(
                Detection(
                    box,
                    float(dec.scores[keep[i]]),
                    name,
                    mask=None if masks is None else masks[i],
                    edge_sigma_px=sigma,
                )
            )
        self.last_reason = "" if out else "no vehicle above the score threshold"
        return out

    def _masks_to_frame(
        self, small: NDArray[np.bool_], lb: Letterbox, w: int, h: int
    ) -> NDArray[np.bool_]:
        """Prototype-resolution masks to full-frame boolean masks (undo the letterbox)."""
        m = small.shape[0]
        mh, mw = small.shape[1:]
        sx, sy = mw / self.width, mh / self.height
        # frame pixel -> input pixel -> prototype pixel: one affine map for all masks
        M = np.array(
            [
                [lb.sx * sx, 0.0, lb.px * sx + 0.5 * lb.sx * sx - 0.5],
                [0.0, lb.sy * sy, lb.py * sy + 0.5 * lb.sy * sy - 0.5],
            ],
            np.float64,
        )
        out = np.empty((m, h, w), bool)
        for i in range(m):  # a handful of detections
            warped = cv2.warpAffine(
                small[i].astype(np.uint8),
                M,
                (w, h),
                flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                borderValue=0,
            )
            out[i] = warped > 0
        return out
