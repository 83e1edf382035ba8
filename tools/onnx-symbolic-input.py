#!/usr/bin/env python3
"""Give an ONNX model's image input symbolic height and width, and change nothing else.

    python3 tools/onnx-symbolic-input.py IN.onnx OUT.onnx [HEIGHT_NAME WIDTH_NAME]

The input must be one 4-D tensor, N x C x H x W, with H and W fixed numbers; they become the names given
(default "height" and "width"), so ONNX Runtime accepts any input size the graph itself allows (YOLOX: any
multiple of 32). Every other byte stays: the script checks that setting the two dimensions back to their
numbers gives the input file byte for byte, and prints both files' sha256.

It needs the `onnx` Python package (made with onnx 1.23.2):
    python3 -m venv /tmp/onnx-venv && /tmp/onnx-venv/bin/pip install onnx==1.23.2
    /tmp/onnx-venv/bin/python tools/onnx-symbolic-input.py fixtures/yolox_nano/yolox_nano.onnx out.onnx
"""

import hashlib
import sys

import onnx


def main(argv):
    if len(argv) not in (3, 5):
        sys.exit(__doc__)
    src, dst = argv[1], argv[2]
    names = argv[3:5] if len(argv) == 5 else ["height", "width"]
    original = open(src, "rb").read()
    model = onnx.load_from_string(original)
    if model.SerializeToString() != original:
        sys.exit(f"{src}: does not read back byte for byte with this onnx package; nothing written")
    inputs = model.graph.input
    if len(inputs) != 1:
        sys.exit(f"{src}: {len(inputs)} inputs; this script handles a model with one image input")
    dims = inputs[0].type.tensor_type.shape.dim
    if len(dims) != 4 or not all(d.HasField("dim_value") for d in dims[2:]):
        sys.exit(f"{src}: input {inputs[0].name} is not N x C x H x W with fixed H and W")
    fixed = [dims[2].dim_value, dims[3].dim_value]
    for d, name in zip(dims[2:], names):
        d.dim_param = name  # a oneof: this clears dim_value
    onnx.checker.check_model(model)
    out = model.SerializeToString()

    # nothing else changed: the two dimensions set back give the original bytes
    back = onnx.load_from_string(out)
    for d, value in zip(back.graph.input[0].type.tensor_type.shape.dim[2:], fixed):
        d.dim_value = value
    if back.SerializeToString() != original:
        sys.exit("the edited model differs from the original in more than the input's height and width")

    with open(dst, "wb") as f:
        f.write(out)
    print(f"{src}: {len(original)} bytes, sha256 {hashlib.sha256(original).hexdigest()}, input "
          f"{inputs[0].name} 1x3x{fixed[0]}x{fixed[1]}")
    print(f"{dst}: {len(out)} bytes, sha256 {hashlib.sha256(out).hexdigest()}, input "
          f"{inputs[0].name} 1x3x{names[0]}x{names[1]}")


if __name__ == "__main__":
    main(sys.argv)
