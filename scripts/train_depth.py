"""Train the small single-image depth network on the simulator data set and export assets/models/depth_small.onnx.

Owns the network (a U-Net-ish encoder-decoder), the MiDaS-style scale-and-shift-invariant loss, the ONNX export
and the model card (assets/models/depth_small.md). torch is needed here only (the `train` extra).

Usage: python scripts/make_depth_dataset.py && python scripts/train_depth.py [--epochs 16]
"""

from __future__ import annotations

import argparse
import hashlib
import platform
import sys
import time
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from trade.single_image_depth import (  # noqa: E402
    DEFAULT_INPUT_SIZE_PX, DEFAULT_MODEL, SingleImageDepth, depth_metrics_after_alignment, to_network_input,
    valid_depth_mask,
)
from trade_gym.bench.splits import require_training_worlds  # noqa: E402
from trade_gym.recording.reader import open_sequence  # noqa: E402

SEED = 1234
# torch intra-op threads. 1 by default: measured with another job holding one of the 2 cores, 2 threads ran a
# training step 10x slower (156 vs 11-15 ms per image, OpenMP threads waiting on each other); use --threads 2 on
# an idle machine.
DEFAULT_THREADS = 1
OPSET = 17
ENCODER_CHANNELS = (16, 32, 64, 128, 128)  # each stage halves the resolution (128 -> 4 px)
DECODER_CHANNELS = (64, 48, 32)  # upsample x2, concatenate the skip, conv; output at 32 px
OUTPUT_UPSAMPLE = 4.0  # bilinear, 32 -> 128 px
GRAD_SCALES = 4  # gradient-matching term on the residual at strides 1, 2, 4, 8
GRAD_WEIGHT = 0.5
ALIGN_EPS = 1e-6  # added to var(pred) in the per-image scale solve
BRIGHTNESS_JITTER = 0.1  # additive, in rgb / 255
CONTRAST_JITTER = 0.1  # multiplicative about 0.5
NOISE_STD_U8 = 3.0  # Gaussian pixel noise [grey levels]
MAX_ABS_ONNX_DIFF = 1e-4
TIMING_CALLS = 200
ONNX_CHECK_FRAMES = 8  # held-out frames run through both torch and ONNX after export
DATA_DIR = Path(__file__).resolve().parents[1] / "build" / "depth_dataset"


def conv_bn_relu(c_in: int, c_out: int, stride: int = 1) -> nn.Sequential:
    return nn.Sequential(nn.Conv2d(c_in, c_out, 3, stride, 1, bias=False), nn.BatchNorm2d(c_out), nn.ReLU(inplace=True))


class DepthNet(nn.Module):
    """(N, 3, S, S) normalised RGB -> (N, 1, S, S) relative inverse depth >= 0 (softplus output)."""

    def __init__(self) -> None:
        super().__init__()
        c = ENCODER_CHANNELS
        # stage 0: one strided conv (64 px); later stages: strided conv + conv
        stages = [conv_bn_relu(3, c[0], 2)]
        stages += [nn.Sequential(conv_bn_relu(c[k - 1], c[k], 2), conv_bn_relu(c[k], c[k])) for k in range(1, len(c))]
        self.encoder = nn.ModuleList(stages)
        decoder, prev = [], c[-1]
        for k, width in enumerate(DECODER_CHANNELS):
            decoder.append(conv_bn_relu(prev + c[len(c) - 2 - k], width))
            prev = width
        self.decoder = nn.ModuleList(decoder)
        self.head = nn.Conv2d(prev, 1, 3, 1, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        skips = []
        for stage in self.encoder:
            x = stage(x)
            skips.append(x)
        for k, stage in enumerate(self.decoder):
            skip = skips[len(skips) - 2 - k]
            x = F.interpolate(x, size=skip.shape[-2:], mode="bilinear", align_corners=False)
            x = stage(torch.cat([x, skip], 1))
        x = F.interpolate(self.head(x), scale_factor=OUTPUT_UPSAMPLE, mode="bilinear", align_corners=False)
        return F.softplus(x)


def ssi_loss(pred: torch.Tensor, target_inv: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """Scale-and-shift-invariant loss on inverse depth, all (N, 1, H, W).

    Per image: (s, t) = argmin sum_mask (s p + t - r)^2 (closed form); residual e = (s p + t - r) / mean_mask(r);
    loss = mean_mask |e| + GRAD_WEIGHT * sum_k mean |grad e| at stride 2^k (MiDaS gradient matching).
    """
    n = mask.sum((1, 2, 3), keepdim=True).clamp_min(1.0)
    p_mean = (pred * mask).sum((1, 2, 3), keepdim=True) / n
    r_mean = (target_inv * mask).sum((1, 2, 3), keepdim=True) / n
    dp, dr = (pred - p_mean) * mask, (target_inv - r_mean) * mask
    s = (dp * dr).sum((1, 2, 3), keepdim=True) / ((dp * dp).sum((1, 2, 3), keepdim=True) + ALIGN_EPS)
    e = (s * (pred - p_mean) + r_mean - target_inv) * mask / r_mean.clamp_min(ALIGN_EPS)
    loss = e.abs().sum() / n.sum()
    for k in range(GRAD_SCALES):
        step = 2**k
        ek, mk = e[..., ::step, ::step], mask[..., ::step, ::step]
        gx = (ek[..., :, 1:] - ek[..., :, :-1]).abs() * mk[..., :, 1:] * mk[..., :, :-1]
        gy = (ek[..., 1:, :] - ek[..., :-1, :]).abs() * mk[..., 1:, :] * mk[..., :-1, :]
        loss = loss + GRAD_WEIGHT * (gx.sum() + gy.sum()) / mk.sum().clamp_min(1.0)
    return loss


def augment(rgb: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """(B, H, W, 3) uint8 -> jittered uint8 batch and (B,) horizontal-flip flags (depth flipped by the caller)."""
    b = len(rgb)
    x = rgb.astype(np.float32) / 255.0
    contrast = rng.uniform(1.0 - CONTRAST_JITTER, 1.0 + CONTRAST_JITTER, (b, 1, 1, 1)).astype(np.float32)
    bright = rng.uniform(-BRIGHTNESS_JITTER, BRIGHTNESS_JITTER, (b, 1, 1, 1)).astype(np.float32)
    x = (x - 0.5) * contrast + 0.5 + bright + rng.normal(0.0, NOISE_STD_U8 / 255.0, x.shape).astype(np.float32)
    flip = rng.random(b) < 0.5
    x[flip] = x[flip, :, ::-1]
    return np.clip(np.rint(x * 255.0), 0, 255).astype(np.uint8), flip


def load_split(path: Path) -> dict[str, np.ndarray]:
    """A split written by make_depth_dataset.py: every sequence folder in `path` (docs/sequence_format.md, each
    with a depth layer), stacked: rgb (N, H, W, 3) uint8, depth_m (N, H, W) float32 [m], scene (N,) str, seed
    (N,) int; far_m (the layers' no-hit depth, one for all) and render_s (summed) scalars. Training worlds only."""
    folders = sorted(f for f in path.iterdir() if f.is_dir() and not f.name.startswith(".")) if path.is_dir() else []
    if not folders:
        raise SystemExit(f"{path}: no sequence folders (run scripts/make_depth_dataset.py)")
    rows: dict[str, list] = {"rgb": [], "depth_m": [], "scene": [], "seed": []}
    far, render_s = set(), 0.0
    for folder in folders:
        sequence = open_sequence(folder)
        seed = sequence.meta["seeds"]["world_seed"]
        require_training_worlds([seed], "depth training")
        far.add(sequence.meta["layers"]["depth"]["no_hit_m"])
        render_s += float(sequence.meta["source"].get("render_s", 0.0))
        for frame in sequence:
            rows["rgb"].append(sequence.rgb(frame))
            depth = sequence.depth_m(frame)
            if depth is None:
                raise SystemExit(f"{folder}: frame {frame.index} has no depth layer")
            rows["depth_m"].append(depth)
            rows["scene"].append(sequence.meta["scene"])
            rows["seed"].append(seed)
    if len(far) != 1:
        raise SystemExit(f"{path}: the sequences disagree on the no-hit depth (layers.depth.no_hit_m: {sorted(far)})")
    return {"rgb": np.stack(rows["rgb"]), "depth_m": np.stack(rows["depth_m"]), "scene": np.array(rows["scene"]),
            "seed": np.array(rows["seed"], dtype=np.int64), "far_m": np.float32(far.pop()),
            "render_s": np.float32(render_s)}


def targets(depth_m: np.ndarray, far_m: float) -> tuple[torch.Tensor, torch.Tensor]:
    """(N, H, W) depth [m] -> (N, 1, H, W) inverse depth [1/m] (0 on sky) and valid mask, float32."""
    d = depth_m.astype(np.float32)
    valid = valid_depth_mask(d, far_m)
    inv = np.where(valid, 1.0 / np.where(valid, d, 1.0), 0.0).astype(np.float32)
    return torch.from_numpy(inv[:, None]), torch.from_numpy(valid[:, None].astype(np.float32))


def predict_torch(net: DepthNet, rgb: np.ndarray, batch: int = 50) -> np.ndarray:
    net.eval()
    with torch.no_grad():
        out = [net(torch.from_numpy(to_network_input(rgb[i:i + batch]))) for i in range(0, len(rgb), batch)]
    return torch.cat(out).numpy()[:, 0]


def evaluate(pred_inv: np.ndarray, data: dict[str, np.ndarray]) -> dict[str, tuple[float, float, int]]:
    """Mean per-frame (AbsRel, delta1, frames) after alignment, overall ("all") and per scene."""
    far = float(data["far_m"])
    rows = [depth_metrics_after_alignment(p, d.astype(np.float32), valid_depth_mask(d, far))
            for p, d in zip(pred_inv, data["depth_m"])]
    out = {}
    for name in ("all", *sorted(set(data["scene"].tolist()))):
        sel = [r for r, s in zip(rows, data["scene"]) if name in ("all", s)]
        out[name] = (float(np.mean([r.abs_rel for r in sel])), float(np.mean([r.delta1 for r in sel])), len(sel))
    return out


def train(net: DepthNet, train_data: dict, heldout: dict, args: argparse.Namespace) -> tuple[int, float]:
    """Adam with cosine decay; one progress line per epoch. Returns (epochs run, wall time [s])."""
    rng = np.random.default_rng(SEED)
    far = float(train_data["far_m"])
    inv_all, mask_all = targets(train_data["depth_m"], far)
    n = len(train_data["rgb"])
    steps_per_epoch = n // args.batch
    opt = torch.optim.Adam(net.parameters(), lr=args.lr)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=args.lr, total_steps=args.epochs * steps_per_epoch,
                                                pct_start=0.1)
    start = time.perf_counter()
    for epoch in range(args.epochs):
        net.train()
        order, total = rng.permutation(n), 0.0
        for b in range(steps_per_epoch):
            idx = np.sort(order[b * args.batch:(b + 1) * args.batch])
            rgb, flip = augment(train_data["rgb"][idx], rng)
            inv, mask = inv_all[idx].clone(), mask_all[idx].clone()
            fl = torch.from_numpy(flip)
            inv[fl], mask[fl] = inv[fl].flip(-1), mask[fl].flip(-1)
            loss = ssi_loss(net(torch.from_numpy(to_network_input(rgb))), inv, mask)
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
            total += loss.item()
        metrics = evaluate(predict_torch(net, heldout["rgb"]), heldout)["all"]
        elapsed = time.perf_counter() - start
        print(f"epoch {epoch + 1}/{args.epochs}: loss {total / steps_per_epoch:.4f}, held-out AbsRel "
              f"{metrics[0]:.4f} delta1 {metrics[1]:.4f}, {elapsed:.0f} s", flush=True)
        if elapsed > args.max_minutes * 60.0 and epoch + 1 < args.epochs:
            print(f"stopping early: wall-time budget of {args.max_minutes} min exceeded", flush=True)
            return epoch + 1, elapsed
    return args.epochs, time.perf_counter() - start


def export(net: DepthNet, path: Path, sample: np.ndarray) -> float:
    """Write ONNX (opset 17, dynamic batch) and return max |onnx - torch| on `sample` (N, H, W, 3) uint8."""
    import onnxruntime as ort

    net.eval()
    size = DEFAULT_INPUT_SIZE_PX
    path.parent.mkdir(parents=True, exist_ok=True)
    torch.onnx.export(net, (torch.zeros(1, 3, size, size),), str(path), opset_version=OPSET, dynamo=False,
                      input_names=["rgb"], output_names=["inverse_depth"],
                      dynamic_axes={"rgb": {0: "batch"}, "inverse_depth": {0: "batch"}})
    x = to_network_input(sample)
    session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    (onnx_out,) = session.run(None, {"rgb": x})
    with torch.no_grad():
        torch_out = net(torch.from_numpy(x)).numpy()
    return float(np.max(np.abs(onnx_out - torch_out)))


def time_runtime(model: SingleImageDepth, rgb: np.ndarray) -> float:
    """Median wall time of one `predict` call [ms] over TIMING_CALLS calls (after a warm-up)."""
    model.predict(rgb[0])
    times = []
    for k in range(TIMING_CALLS):
        t = time.perf_counter()
        model.predict(rgb[k % len(rgb)])
        times.append(time.perf_counter() - t)
    return 1000.0 * float(np.median(times))


_CARD_LIMITS = """## Limits
Trained only on trade-gym renders (TinyRenderer, three procedural scenes, level body with a pitched camera);
relative inverse depth only, never metric; expect it to fail on real imagery or other renderers.
"""


def write_card(path: Path, info: dict) -> None:
    """Write the model card (markdown) at `path` from the run summary `info` built in `main`."""
    sections = (_card_model(info), _card_data(info), _card_training(info), _card_metrics(info), _CARD_LIMITS)
    path.write_text("\n".join(sections))


def _card_model(info: dict) -> str:
    """Card title and the model: file, hash, input/output, architecture."""
    return f"""# depth_small.onnx: single-image relative inverse depth (model card)

Small U-Net-ish encoder-decoder standing in for MiDaS (paper, "Single-Image Depth"): RGB in, relative
inverse depth out (an unknown affine map of 1 / z; align it with `trade.depth_alignment`). Trained here from
scratch on simulator renders (no pretrained weights); it knows only trade-gym's three scenes.

- File: `assets/models/depth_small.onnx`, {info['bytes']} bytes, SHA-256 `{info['sha256']}`
  (checked on load by `trade.single_image_depth.SingleImageDepth`; constant `DEFAULT_MODEL_SHA256`).
- Input `rgb`: float32 (N, 3, 128, 128), (rgb / 255 - mean) / std with ImageNet mean/std
  (`trade.single_image_depth.to_network_input`). Output `inverse_depth`: float32 (N, 1, 128, 128), >= 0.
- Architecture: encoder {ENCODER_CHANNELS} (3x3 conv-BN-ReLU, stride 2; stages after the first add a second conv), decoder
  {DECODER_CHANNELS} (bilinear x2, skip concat, conv-BN-ReLU), 3x3 head at 32 px, bilinear x4, softplus;
  {info['params']} parameters. ONNX opset {OPSET}, dynamic batch.
"""


def _card_data(info: dict) -> str:
    """Card section: how the training and held-out frames were rendered."""
    return f"""## Data (scripts/make_depth_dataset.py)
`python scripts/make_depth_dataset.py` (defaults: 300 train worlds, 25 held-out, 8 views each).
World k of a split: `build_world(cid, ("desert", "city", "mountain")[k % 3], default_rng(seed_base + k))`,
one pybullet DIRECT client reset before each world; 8 views per world from the same generator: vehicles posed at
t ~ U(0, duration); camera xy within 30 m of the target (p = 0.75) or of the drone start; altitude
U(12, 40) m above the surface (roofs included); yaw U(-pi, pi); mount pitch U(60, 90) deg; 128 x 128 px,
110 deg vertical FOV, TinyRenderer. Train: seeds {info['train_seeds']}, {info['train_frames']} frames.
Held-out: seeds {info['heldout_seeds']}, {info['heldout_frames']} frames. The benchmark evaluates seeds 0..99
(disjoint). Render time (world builds + renders, one core): {info['render_s']}.
"""


def _card_training(info: dict) -> str:
    """Card section: command, loss, augmentation, optimiser, machine and export check."""
    return f"""## Training (scripts/train_depth.py)
`{info['command']}`
Loss: MiDaS scale-and-shift-invariant loss on inverse depth (per-image least-squares alignment, L1 of the
residual relative to the image's mean inverse depth) + {GRAD_WEIGHT} x gradient matching at {GRAD_SCALES} scales;
sky pixels (depth >= 0.99 far) masked. Augmentation: horizontal flip, brightness/contrast jitter, pixel noise.
Adam, one-cycle LR (max {info['lr']}), batch {info['batch']}, {info['epochs']} epochs, seed {SEED},
torch {torch.__version__} with {info['threads']} thread(s) on {info['cpu']}: {info['train_s']:.0f} s wall time.
Max |ONNX - torch| on {ONNX_CHECK_FRAMES} held-out frames: {info['onnx_diff']:.2e}.
"""


def _card_metrics(info: dict) -> str:
    """Card section: held-out AbsRel and delta1 per scene group, and the inference time."""
    rows = "\n".join(f"| {k} | {v[2]} | {v[0]:.4f} | {v[1]:.4f} |" for k, v in info["metrics"].items())
    return f"""## Held-out metrics
Per frame: least-squares scale and shift of the prediction to 1 / depth on valid pixels, aligned inverse depth
capped below at 1 / (frame's max depth), converted to depth; AbsRel = mean |d' - d| / d, delta1 = fraction
with max(d'/d, d/d') < 1.25 (`trade.single_image_depth.depth_metrics_after_alignment`); mean over frames,
run through the exported ONNX model with onnxruntime.

| scenes | frames | AbsRel | delta1 |
| --- | --- | --- | --- |
{rows}

Inference (`SingleImageDepth.predict`, 128 x 128 input, onnxruntime 1 thread): median {info['ms']:.2f} ms per call.
"""


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data-dir", type=Path, default=DATA_DIR)
    ap.add_argument("--out", type=Path, default=DEFAULT_MODEL)
    ap.add_argument("--epochs", type=int, default=16)
    ap.add_argument("--batch", type=int, default=16)
    ap.add_argument("--lr", type=float, default=2e-3)
    ap.add_argument("--threads", type=int, default=DEFAULT_THREADS)
    ap.add_argument("--max-minutes", type=float, default=13.0, help="stop after the epoch that exceeds this")
    args = ap.parse_args(argv)
    torch.manual_seed(SEED)
    torch.set_num_threads(args.threads)
    train_data, heldout = load_split(args.data_dir / "train"), load_split(args.data_dir / "heldout")
    net = DepthNet()
    params = sum(p.numel() for p in net.parameters())
    print(f"{len(train_data['rgb'])} train / {len(heldout['rgb'])} held-out frames, {params} parameters", flush=True)
    epochs, train_s = train(net, train_data, heldout, args)
    diff = export(net, args.out, heldout["rgb"][:ONNX_CHECK_FRAMES])
    print(f"max |onnx - torch| = {diff:.2e} (bound {MAX_ABS_ONNX_DIFF:g})", flush=True)
    if not diff <= MAX_ABS_ONNX_DIFF:
        raise SystemExit(f"ONNX export differs from torch by {diff:.2e} > {MAX_ABS_ONNX_DIFF:g}")
    data = args.out.read_bytes()
    sha = hashlib.sha256(data).hexdigest()
    runtime = SingleImageDepth(args.out, sha)
    metrics = evaluate(np.stack([runtime.predict(rgb) for rgb in heldout["rgb"]]), heldout)
    ms = time_runtime(runtime, heldout["rgb"])
    info = dict(bytes=len(data), sha256=sha, params=params, metrics=metrics, ms=ms, epochs=epochs, train_s=train_s,
                onnx_diff=diff, threads=args.threads, lr=args.lr, batch=args.batch,
                cpu=platform.processor() or platform.machine(),
                train_frames=len(train_data["rgb"]), heldout_frames=len(heldout["rgb"]),
                train_seeds=f"{train_data['seed'].min()}..{train_data['seed'].max()}",
                render_s=f"train {float(train_data['render_s']):.0f} s, held-out {float(heldout['render_s']):.0f} s",
                heldout_seeds=f"{heldout['seed'].min()}..{heldout['seed'].max()}",
                command=" ".join(["python scripts/train_depth.py", *(argv if argv is not None else sys.argv[1:])]))
    write_card(args.out.with_suffix(".md"), info)
    for name, (abs_rel, delta1, frames) in metrics.items():
        print(f"held-out {name}: AbsRel {abs_rel:.4f} delta1 {delta1:.4f} ({frames} frames)")
    print(f"{args.out}: {len(data)} bytes, SHA-256 {sha}; predict median {ms:.2f} ms; "
          f"set trade.single_image_depth.DEFAULT_MODEL_SHA256 to this hash", flush=True)


if __name__ == "__main__":
    main()
