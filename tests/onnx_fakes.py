"""Small ONNX graphs of the wrong shape, for the model checks (built with the onnx package, run by onnxruntime)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper


def _save(graph, path: Path) -> Path:
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    onnx.checker.check_model(model)
    onnx.save(model, str(path))
    return path


def wrong_input_model(path: Path) -> Path:
    """Input 'albedo_rgb' of shape (N, 4): not docs/contracts.md §3."""
    x = helper.make_tensor_value_info("albedo_rgb", TensorProto.FLOAT, ["N", 4])
    y = helper.make_tensor_value_info("reflectance", TensorProto.FLOAT, ["N", 4])
    return _save(helper.make_graph([helper.make_node("Identity", ["albedo_rgb"], ["reflectance"])], "bad", [x], [y]),
                 path)


def missing_outputs_model(path: Path) -> Path:
    """Right input, but only a 'reflectance' output of 376 samples (x times a constant row)."""
    x = helper.make_tensor_value_info("albedo_rgb", TensorProto.FLOAT, ["N", 3])
    y = helper.make_tensor_value_info("reflectance", TensorProto.FLOAT, ["N", 376])
    w = numpy_helper.from_array(np.full((3, 376), 0.1, np.float32), "w")
    node = helper.make_node("MatMul", ["albedo_rgb", "w"], ["reflectance"])
    return _save(helper.make_graph([node], "partial", [x], [y], initializer=[w]), path)
