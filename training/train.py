"""Train the learned detector's network and export it for the detector (``balltrack train``).

1. Samples (``data.py``): ``--pictures`` randomised renders, made in chunks of
   ``CHUNK`` pictures, each chunk seeded from ``--seed`` and its index (the same samples
   whatever the number of worker processes), and the photo sets that may be trained on (under
   ``--photos``), each photo ``--photo-copies`` times. Another ``--check-pictures`` renders,
   from another seed, are kept aside to report on.
2. Training (torch, CPU): ``--epochs`` passes, Adam, cosine learning rate, seeded; loss: binary
   cross-entropy on ball / not a ball (positives weighted up to their share), and a smooth L1
   loss on the corrections of balls. Pictures are flipped left-right at random; nothing else is
   learned from the development photos, and no checkpoint is chosen by them: the last epoch's
   network is the one exported.
3. Export: ``ball_network.onnx`` (run by OpenCV's dnn module, no torch needed) and its model
   card, ``ball_network.md``: the data, the settings and the figures on the renders kept aside.

Example::

    pip install -e '.[train]'
    balltrack train --out services/detector/models
    python -m balltrack.training.train --pictures 400 --epochs 2 --out /tmp/model   # a quick try
"""

import argparse
import datetime
import json
import math
import os
import platform
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from pathlib import Path

import numpy as np

from balltrack.common.arguments import ArgumentParser, integer
from balltrack.experiments.base import PHOTOS_DEFAULT_TEXT, development_photos
from balltrack.services.detector.learned import CONTEXT, PATCH, PLANES, WORK_WIDTH_KEY
from balltrack.training.data import TRAINABLE_SETS, WORK_WIDTH, Samples, photo_samples, render_samples

CHUNK = 100
# The committed model's processing width: half the detector's work_width, for speed (the mask,
# proposals and patches of a quarter of the pixels).
MODEL_WORK_WIDTH = 320
MODEL_NAME = "ball_network"


def build_network():
    """The network: four small convolutions and two dense layers (about 0.8 M multiply-adds a
    patch); outputs the ball logit and the corrections dx, dy, log radius ratio."""
    from torch import nn

    def block(inputs: int, outputs: int, stride: int = 1):
        return [nn.Conv2d(inputs, outputs, 3, stride=stride, padding=1, bias=False), nn.BatchNorm2d(outputs),
                nn.ReLU(inplace=True)]

    return nn.Sequential(
        *block(PLANES, 12, stride=2),          # 16 x 16
        *block(12, 24), nn.MaxPool2d(2),       # 8 x 8
        *block(24, 32), nn.MaxPool2d(2),       # 4 x 4
        *block(32, 48),
        nn.Flatten(), nn.Linear(48 * 4 * 4, 48), nn.ReLU(inplace=True), nn.Linear(48, 4))


def _render_chunk(arguments: tuple[int, int, int]) -> Samples:
    pictures, seed, work_width = arguments
    os.environ.setdefault("MUJOCO_GL", "egl")
    return render_samples(pictures, seed, work_width=work_width)


def make_samples(pictures: int, seed: int, workers: int, work_width: int = WORK_WIDTH) -> Samples:
    """Render samples of ``pictures`` pictures in chunks (see the module doc)."""
    chunks = [(min(CHUNK, pictures - start), seed * 100_003 + index, work_width)
              for index, start in enumerate(range(0, pictures, CHUNK))]
    if workers <= 1:
        return Samples.join([_render_chunk(chunk) for chunk in chunks])
    with ProcessPoolExecutor(workers, mp_context=get_context("spawn")) as pool:
        return Samples.join(list(pool.map(_render_chunk, chunks)))


def flip_left_right(inputs, corrections):
    inputs = inputs.flip(-1)
    corrections = corrections.clone()
    corrections[:, 0] = -corrections[:, 0]
    return inputs, corrections


def figures(network, samples: Samples, threshold: float = 0.5) -> dict:
    """Share of balls accepted, of not-balls rejected, and the median centre error (radii) of
    accepted balls, on samples the network was not trained on."""
    import torch

    known = samples.labels >= 0
    inputs = torch.from_numpy(samples.inputs[known].astype(np.float32))
    labels = samples.labels[known]
    network.eval()
    with torch.no_grad():
        outputs = torch.cat([network(inputs[start:start + 4096]) for start in range(0, len(inputs), 4096)]).numpy()
    accepted = 1 / (1 + np.exp(-outputs[:, 0])) >= threshold
    balls = labels == 1
    error = np.hypot(*(outputs[balls & accepted, 1:3] - samples.corrections[known][balls & accepted, :2]).T)
    return {"balls": int(balls.sum()), "not_balls": int((~balls).sum()),
            "balls_accepted": round(float(accepted[balls].mean()) if balls.any() else 0.0, 4),
            "not_balls_rejected": round(float((~accepted[~balls]).mean()) if (~balls).any() else 0.0, 4),
            "median_centre_error_radii": round(float(np.median(error)) if len(error) else 0.0, 4)}


def train(samples: Samples, epochs: int, seed: int, batch: int = 256, rate: float = 3e-3, log=print):
    import torch
    from torch import nn

    torch.manual_seed(seed)
    generator = torch.Generator().manual_seed(seed)
    network = build_network()
    known = samples.labels >= 0
    inputs = torch.from_numpy(samples.inputs[known])
    labels = torch.from_numpy((samples.labels[known] == 1).astype(np.float32))
    corrections = torch.from_numpy(samples.corrections[known])
    positive_weight = torch.tensor(float((labels == 0).sum()) / max(1.0, float(labels.sum())))
    optimiser = torch.optim.Adam(network.parameters(), lr=rate, weight_decay=1e-4)
    steps = epochs * math.ceil(len(labels) / batch)
    schedule = torch.optim.lr_scheduler.OneCycleLR(optimiser, max_lr=rate, total_steps=max(1, steps))
    classify = nn.BCEWithLogitsLoss(pos_weight=positive_weight.sqrt())
    for epoch in range(epochs):
        network.train()
        order = torch.randperm(len(labels), generator=generator)
        started, total = time.perf_counter(), 0.0
        for start in range(0, len(order), batch):
            chosen = order[start:start + batch]
            x, y, c = inputs[chosen].float(), labels[chosen], corrections[chosen]
            if torch.rand(1, generator=generator).item() < 0.5:
                x, c = flip_left_right(x, c)
            out = network(x)
            loss = classify(out[:, 0], y)
            if y.sum() > 0:
                loss = loss + 2.0 * nn.functional.smooth_l1_loss(out[y > 0, 1:], c[y > 0], beta=0.1)
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()
            schedule.step()
            total += float(loss.detach()) * len(chosen)
        log(f"epoch {epoch + 1}/{epochs}: loss {total / len(order):.4f} ({time.perf_counter() - started:.0f} s)")
    return network


def export(network, path: Path, work_width: int = WORK_WIDTH) -> None:
    """The network as ONNX with a free batch size (opset 13: OpenCV's dnn reads it), and in its
    metadata the width its pictures were processed at (``learned.WORK_WIDTH_KEY``)."""
    import onnx
    import torch

    network.eval()
    example = torch.zeros(1, PLANES, PATCH, PATCH)
    torch.onnx.export(network, example, str(path), input_names=["patches"], output_names=["outputs"],
                      dynamic_axes={"patches": {0: "batch"}, "outputs": {0: "batch"}}, opset_version=13,
                      dynamo=False)
    model = onnx.load(str(path))
    onnx.helper.set_model_props(model, {WORK_WIDTH_KEY: str(work_width)})
    onnx.save(model, str(path))


def model_card(settings: dict, counts: dict, check: dict, seconds: float) -> str:
    lines = [
        f"# {MODEL_NAME}: the learned detector's network",
        "",
        "Written by `balltrack train` (training/train.py); do not edit by hand.",
        "",
        f"- Trained: {datetime.date.today().isoformat()} on {platform.machine()}, "
        f"{os.cpu_count()} cores, in {seconds / 60:.1f} min (samples and training).",
        f"- Input: {PLANES} planes of {PATCH} x {PATCH} px (brightness normalised per patch, chroma, "
        f"colour mask, hue position in the configured range), a square of {CONTEXT} radii around each proposal. "
        "Output: ball logit; centre correction (radii); log radius ratio.",
        "- Settings: " + ", ".join(f"{key} {value}" for key, value in settings.items()) + ".",
        "",
        "## Data",
        "",
        "| source | samples | balls | not balls | left out |",
        "| --- | --- | --- | --- | --- |",
    ]
    for source, (total, balls, not_balls, left_out) in counts.items():
        lines.append(f"| {source} | {total} | {balls} | {not_balls} | {left_out} |")
    lines += [
        "",
        "Renders: randomised MuJoCo worlds (training/scenes.py) with camera effects (training/augment.py). "
        f"Photos: {', '.join(TRAINABLE_SETS)} (their READMEs allow training; attribution in them: "
        "MIT, Copyright (c) 2026 Zhiyuan Xing; Apache-2.0, Copyright 2019-2024 Andre Pool). "
        "No development photo set was read.",
        "",
        "## Figures on renders kept aside (another seed)",
        "",
        "| figure | value |",
        "| --- | --- |",
    ]
    lines += [f"| {key} | {value} |" for key, value in check.items()]
    lines += ["", "Figures on the photo sets: `balltrack experiment real_photos` (docs/results.md).", ""]
    return "\n".join(lines)


def _counts(samples: Samples) -> tuple[int, int, int, int]:
    labels = samples.labels
    return len(labels), int((labels == 1).sum()), int((labels == 0).sum()), int((labels == -1).sum())


def main(argv: list[str] | None = None) -> int:
    parser = ArgumentParser(prog="balltrack train", description=__doc__.split("\n\n")[0],
                            formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, required=True, help="folder for ball_network.onnx and ball_network.md")
    parser.add_argument("--pictures", type=integer(minimum=1), default=8000,
                        help="randomised renders to train on (default 8000)")
    parser.add_argument("--check-pictures", type=integer(minimum=1), default=400,
                        help="renders kept aside to report on (default 400)")
    parser.add_argument("--photos", type=Path, default=None,
                        help=f"folder holding the trainable photo sets (default {PHOTOS_DEFAULT_TEXT}); "
                             "missing sets are skipped")
    parser.add_argument("--photo-copies", type=integer(minimum=1), default=4,
                        help="times each trainable photo is used (default 4)")
    parser.add_argument("--epochs", type=integer(minimum=1), default=12, help="passes over the samples (default 12)")
    parser.add_argument("--seed", type=integer(minimum=0), default=1)
    parser.add_argument("--workers", type=integer(minimum=1), default=2, help="processes that render (default 2)")
    parser.add_argument("--work-width", type=integer(minimum=64), default=MODEL_WORK_WIDTH,
                        help=f"width pictures are processed at (default {MODEL_WORK_WIDTH}); the detector then "
                             "processes frames at most this wide with this model")
    options = parser.parse_args(argv)
    try:
        import torch
    except ImportError:
        print("balltrack train: needs torch (pip install -e '.[train]')", file=sys.stderr)
        return 2
    torch.set_num_threads(max(1, os.cpu_count() or 1))
    started = time.perf_counter()
    photos = development_photos(options.photos)
    parts, counts = [], {}
    samples = make_samples(options.pictures, options.seed, options.workers, options.work_width)
    counts[f"renders ({options.pictures})"] = _counts(samples)
    parts.append(samples)
    for offset, name in enumerate(TRAINABLE_SETS):
        if (photos / name / "labels.json").is_file():
            samples = photo_samples(photos / name, options.photo_copies, options.seed + offset,
                                    work_width=options.work_width)
            counts[f"{name} (x{options.photo_copies})"] = _counts(samples)
            parts.append(samples)
        else:
            print(f"balltrack train: {photos / name} not found; trained without it", file=sys.stderr)
    samples = Samples.join(parts)
    print(f"samples: {_counts(samples)} in {time.perf_counter() - started:.0f} s", flush=True)
    check = make_samples(options.check_pictures, options.seed + 7919, options.workers, options.work_width)
    network = train(samples, options.epochs, options.seed)
    check_figures = figures(network, check)
    print(json.dumps(check_figures), flush=True)
    options.out.mkdir(parents=True, exist_ok=True)
    export(network, options.out / f"{MODEL_NAME}.onnx", options.work_width)
    settings = {"pictures": options.pictures, "photo copies": options.photo_copies, "epochs": options.epochs,
                "seed": options.seed, "work width": options.work_width}
    (options.out / f"{MODEL_NAME}.md").write_text(
        model_card(settings, counts, check_figures, time.perf_counter() - started))
    print(f"wrote {options.out / MODEL_NAME}.onnx and .md in {time.perf_counter() - started:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
