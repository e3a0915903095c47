"""The ONNX finder's parts on synthetic arrays: decoders, letterbox, NMS, shape checks.

No model file is needed except for the last test, which writes a tiny ONNX
graph by hand (protobuf wire format) so that a real onnxruntime session with
unexpected outputs is checked end to end.
"""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from roadpreview.camera import CameraModel
from roadpreview.errors import InputDataError
from roadpreview.vision.onnx import (
    COCO_CLASSES,
    Decoded,
    ModelDescription,
    OnnxFinderConfig,
    OnnxLeadFinder,
    decode_yolov8,
    decode_yolox,
    masks_from_protos,
    nms,
    preprocess,
    validate_session,
    yolox_grids,
)

ROOT = Path(__file__).resolve().parents[2]
VEH = np.array([2, 5, 7])  # car, bus, truck in COCO


def test_yolox_decoder_recovers_a_box_on_its_grid() -> None:
    grids, strides = yolox_grids(416, 416, (8, 16, 32))
    assert grids.shape == (3549, 2)
    raw = np.full((3549, 85), -0.0, np.float32)
    raw[:, 4] = 0.01  # background objectness
    # a car centred at (100, 60) px, 64 x 40 px, on the stride-16 grid cell (6, 3)
    row = 52 * 52 + 3 * 26 + 6
    assert tuple(grids[row]) == (6.0, 3.0)
    assert strides[row] == 16
    raw[row, :4] = [100 / 16 - 6, 60 / 16 - 3, np.log(64 / 16), np.log(40 / 16)]
    raw[row, 4] = 0.9
    raw[row, 5 + 2] = 0.8  # car
    raw[row, 5 + 0] = 0.99  # person scores higher but is not a vehicle class
    dec = decode_yolox(raw, grids, strides, VEH, threshold=0.3)
    assert dec.boxes.shape == (1, 4)
    np.testing.assert_allclose(dec.boxes[0], [68, 40, 132, 80], atol=1e-4)
    assert dec.scores[0] == pytest.approx(0.72, abs=1e-6)
    assert int(dec.classes[0]) == 2


def test_yolov8_decoder_and_class_filter() -> None:
    nc, n = 80, 8400
    raw = np.zeros((4 + nc, n), np.float32)
    raw[:4, 10] = [320, 200, 100, 50]  # cx, cy, w, h
    raw[4 + 7, 10] = 0.6  # truck
    raw[:4, 20] = [50, 50, 10, 10]
    raw[4 + 0, 20] = 0.95  # a person: filtered out
    dec = decode_yolov8(raw, nc, VEH, threshold=0.25)
    np.testing.assert_allclose(dec.boxes, [[270, 175, 370, 225]])
    assert int(dec.classes[0]) == 7


def test_yolov8_seg_masks_from_prototypes_stay_inside_the_box() -> None:
    nc, nm, n = 80, 32, 8400
    raw = np.zeros((4 + nc + nm, n), np.float32)
    raw[:4, 5] = [320, 320, 160, 160]
    raw[4 + 2, 5] = 0.9
    raw[4 + nc, 5] = 1.0  # only the first coefficient
    dec = decode_yolov8(raw, nc, VEH, threshold=0.25, n_coeffs=nm)
    assert dec.coeffs is not None
    assert dec.coeffs.shape == (1, nm)
    protos = np.zeros((nm, 160, 160), np.float32)
    protos[0] = 1.0  # prototype 0 is "on" everywhere
    m = masks_from_protos(dec.coeffs, protos, dec.boxes, (640, 640))
    assert m.shape == (1, 160, 160)
    ys, xs = np.nonzero(m[0])
    # the box 240..400 px at 640 -> 60..100 at 160 (mask cropped to the box)
    assert xs.min() == 60
    assert xs.max() == 99
    assert ys.min() == 60
    assert ys.max() == 99


def test_nms_keeps_one_box_per_vehicle() -> None:
    boxes = np.array([[0, 0, 10, 10], [1, 1, 11, 11], [50, 50, 60, 60]], np.float32)
    dec = Decoded(boxes, np.array([0.9, 0.8, 0.7], np.float32), np.array([2, 7, 2]))
    assert nms(dec, 0.45, 10).tolist() == [0, 2]


@pytest.mark.parametrize("style", ["top-left", "center", "stretch"])
def test_letterbox_round_trip(style: str) -> None:
    frame = np.zeros((375, 1242, 3), np.uint8)
    desc = ModelDescription(letterbox=style, color="BGR", scale=1.0)
    x, lb = preprocess(frame, desc, 416, 416)
    assert x.shape == (1, 3, 416, 416)
    assert x.dtype == np.float32
    box = np.array([[555.0, 190.0, 700.0, 315.0]], np.float32)
    as_input = box.copy()
    as_input[:, 0::2] = box[:, 0::2] * lb.sx + lb.px
    as_input[:, 1::2] = box[:, 1::2] * lb.sy + lb.py
    np.testing.assert_allclose(lb.to_frame(as_input), box, atol=1e-3)
    if style == "top-left":  # the rest of the canvas is padding
        assert lb.px == 0
        assert lb.py == 0
        assert float(x[0, 0, -1, 0]) == 114.0


def _session(
    inputs: list[tuple[str, list[object]]], outputs: list[tuple[str, list[object]]]
) -> SimpleNamespace:
    def items(spec: list[tuple[str, list[object]]]) -> list[SimpleNamespace]:
        return [SimpleNamespace(name=n, shape=s) for n, s in spec]

    return SimpleNamespace(get_inputs=lambda: items(inputs), get_outputs=lambda: items(outputs))


def test_validation_names_tensor_and_expected_shape() -> None:
    desc = ModelDescription(format="yolov8")
    good = _session([("images", [1, 3, 640, 640])], [("output0", [1, 84, 8400])])
    assert validate_session(good, desc, "m.onnx")[1:3] == (640, 640)
    dynamic = _session([("images", [1, 3, 640, 640])], [("output0", ["batch", 84, "anchors"])])
    validate_session(dynamic, desc, "m.onnx")  # symbolic dims are checked at run time
    bad = _session([("images", [1, 3, 640, 640])], [("output0", [1, 3549, 85])])
    with pytest.raises(
        InputDataError, match=r"'output0'.*\[1, 3549, 85\].*expects \[1, 84, 8400\]"
    ):
        validate_session(bad, desc, "m.onnx")
    seg = ModelDescription(format="yolov8-seg")
    no_protos = _session([("images", [1, 3, 640, 640])], [("output0", [1, 116, 8400])])
    with pytest.raises(InputDataError, match=r"mask prototypes.*\[1, 32, 160, 160\]"):
        validate_session(no_protos, seg, "m.onnx")


# -- a real ONNX file with the wrong outputs, written by hand ----------------------------
def _varint(v: int) -> bytes:
    out = bytearray()
    while True:
        b = v & 0x7F
        v >>= 7
        out.append(b | (0x80 if v else 0))
        if not v:
            return bytes(out)


def _field(num: int, payload: bytes | int) -> bytes:
    if isinstance(payload, int):
        return _varint(num << 3) + _varint(payload)
    return _varint(num << 3 | 2) + _varint(len(payload)) + payload


def _value_info(name: str, dims: list[int]) -> bytes:
    shape = b"".join(_field(1, _field(1, d)) for d in dims)  # TensorShapeProto.dim.dim_value
    tensor = _field(1, 1) + _field(2, shape)  # elem_type FLOAT, shape
    return _field(1, name.encode()) + _field(2, _field(1, tensor))


def _identity_model(path: Path) -> None:
    """ModelProto: images [1,3,32,32] -> Identity -> output [1,3,32,32] (not a detector)."""
    node = _field(1, b"images") + _field(2, b"output") + _field(4, b"Identity")
    graph = (
        _field(1, node)
        + _field(2, b"g")
        + _field(11, _value_info("images", [1, 3, 32, 32]))
        + _field(12, _value_info("output", [1, 3, 32, 32]))
    )
    model = _field(1, 7) + _field(8, _field(2, 13)) + _field(7, graph)  # ir 7, opset 13
    path.write_bytes(model)


def test_onnx_file_with_unexpected_outputs_is_rejected(tmp_path: Path) -> None:
    model = tmp_path / "not_a_detector.onnx"
    _identity_model(model)
    cam = CameraModel.from_fov(640, 360, 54.0)
    cfg = OnnxFinderConfig(
        model_path=str(model), description=str(ROOT / "data/models/yolox_nano.toml")
    )
    with pytest.raises(InputDataError) as exc:
        OnnxLeadFinder(cam, cfg)
    msg = str(exc.value)
    assert "'output'" in msg
    assert "[1, 3, 32, 32]" in msg
    assert "expects [1, 3549, 85]" in msg


def test_yolox_description_file_matches_the_documented_layout() -> None:
    desc = ModelDescription.load(ROOT / "data/models/yolox_nano.toml")
    assert desc.format == "yolox"
    assert desc.letterbox == "top-left"
    assert desc.color == "BGR"
    assert desc.class_names == COCO_CLASSES
    assert desc.vehicle_ids.tolist() == [2, 5, 7]
