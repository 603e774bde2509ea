"""Denoiser quality and throughput report (docs/results.md, "Denoiser quality").

    python jobs/bench_denoiser.py                                  # every shipped checkpoint
    python jobs/bench_denoiser.py checkpoints/pointmaze-medium-h5  # one
    python jobs/bench_denoiser.py samples=100 A B                  # 100 plans per task start (default 20)
    python jobs/bench_denoiser.py diffusion.boundary_guidance=8 A  # dotted key=value: every config's override
    python jobs/bench_denoiser.py --throughput options=fp32,bf16,compiled,bf16+compiled   # speed per option
    python jobs/bench_denoiser.py --precision checkpoints/pointmaze-medium-h1   # why plans warp
    python jobs/bench_denoiser.py --cube checkpoints/cube-single-h5   # cube models (also in the default list)
    python jobs/bench_denoiser.py --cube data.episodes=300 A B   # key=value overrides every config (one val split)

Quality, per checkpoint: validation loss (manifest), then 100 unguided and 100 guided plans
(20 per task start, full pyramid schedule = plain Diffusion Forcing sampling; Diffuser
checkpoints: all tokens denoised together, start inpainted): share of plans
without a warp (a step over 0.75 + 0.25 H: the authors' 1.0 dense, 2.0 at H=5), share of plan points inside free
maze cells, share of plans "valid" (no warp, and no step crosses a wall: the value's warp test
sees only the first), share of guided plans that come within 2.0 of the goal. These say whether a
search has anything to work with (the measurements live in jobs/bench/plan_quality.py,
shared with jobs/bench/bench_recipe.py). Cube models get their own table
(plan_quality.cube_plan_quality: unguided plans from 100 validation starts beside the data's
own windows). Throughput: guided DDIM transitions per second.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np
import torch

from fmctd_dist.cli import run
from fmctd_dist.config import REPO_ROOT, Config, apply_override, config_from_dict, validate
from fmctd_dist.denoiser.runtime import option_settings
from fmctd_dist.diffusion.model import DFTransformer
from fmctd_dist.registry import family

sys.path.insert(0, str(Path(__file__).resolve().parent / "bench"))  # the measurements: jobs/bench/plan_quality.py
from plan_quality import SAMPLES_PER_TASK, cube_plan_quality, plan_quality, precision  # noqa: E402


def precision_lines(ckpt: Path, batch: int = 64, timesteps: tuple[int, ...] = ()) -> list[str]:
    """The precision table of one checkpoint (plan_quality.precision) as markdown."""
    p = precision(ckpt, batch, timesteps)
    d = p["data"]
    lines = [f"{p['checkpoint']}: {batch} validation windows; data steps: boundary mean {d['boundary_mean']:.3f} "
             f"max {d['boundary_max']:.3f}, inside mean {d['inside_mean']:.3f} max {d['inside_max']:.3f}",
             "| timestep | x0 RMS error | identity RMS error | error at first / middle / last frame | "
             "boundary step mean / max | inside step mean / max | first frames per unit of start |",
             "|---|---|---|---|---|---|---|"]
    for r in p["rows"]:
        lines.append(f"| {r['timestep']} | {r['x0_rms']:.3f} | {r['identity_rms']:.3f} | "
                     f"{r['first']:.2f} / {r['middle']:.2f} / {r['last']:.2f} | "
                     f"{r['boundary_mean']:.3f} / {r['boundary_max']:.2f} | {r['inside_mean']:.3f} / "
                     f"{r['inside_max']:.2f} | {r['start_sensitivity']:.3f} |")
    return lines


# name -> (diffusion.precision, diffusion.compile)
OPTIONS = {n: option_settings(n) for n in ("fp32", "bf16", "compiled", "bf16+compiled")}


def checkpoint_config(ckpt: Path, overrides: list[str]) -> Config | None:
    """The checkpoint's own config with dotted ``key=value`` overrides (e.g. ``data.episodes=300``, so models
    trained on different data sizes are measured on one validation split, or a sampling lever such as
    ``diffusion.boundary_guidance=8``); None when there are none."""
    if not overrides:
        return None
    from omegaconf import OmegaConf

    cfg = OmegaConf.structured(config_from_dict(json.loads((ckpt / "manifest.json").read_text())["config"]))
    for word in overrides:
        key, _, value = word.partition("=")
        cfg = apply_override(cfg, key, value)
    out: Config = OmegaConf.to_object(cfg)  # type: ignore[assignment]
    validate(out)
    return out


def cube_lines(ckpts: list[Path], overrides: list[str] = ()) -> list[str]:
    """The cube quality table (plan_quality.cube_plan_quality) as markdown: model plans, then the data's."""
    lines = ["| checkpoint | steps | val loss | train h | warp | plans of | no warp | cubes supported at the end | "
             "at most one cube moved | some cube moved | boundary / inside step | largest step |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for ckpt in ckpts:
        r = cube_plan_quality(ckpt, checkpoint_config(ckpt, list(overrides)))
        for who in ("model", "data"):
            q = r[who]
            lines.append(f"| {r['checkpoint']} | {r['steps']} | {r['val_loss']:.4f} | {r['train_h']:.2f} | "
                         f"{r['warp']:.2f} | "
                         f"{who} | {100 * q['no_warp']:.0f}% | {100 * q['supported_end']:.0f}% | "
                         f"{100 * q['one_mover']:.0f}% | {100 * q['moved']:.0f}% | "
                         f"{q['boundary_step']:.3f} / {q['inside_step']:.3f} | {q['max_step']:.2f} |")
    return lines


CLOCKS = {"wall": time.perf_counter, "cpu": time.process_time}


def peak_flops(dtype: torch.dtype, device: str = "cpu", n_max: int = 2048, reps: int = 5, clock: str = "wall",
               budget_s: float = 2.0) -> tuple[float, int]:
    """FLOP/s of a large square matmul in ``dtype``: the machine's practical peak, measured in this run.

    The side n doubles from 256 up to ``n_max`` while ``reps`` products stay within ``budget_s``:
    where a dtype is emulated (bf16 on a CPU without avx512_bf16/amx_bf16, ~100x slower) a 2048^3
    product alone takes tens of seconds. Returns (FLOP/s, n used)."""
    now = CLOCKS[clock]
    n = 256
    while True:
        a, b = torch.randn(n, n, device=device).to(dtype), torch.randn(n, n, device=device).to(dtype)
        if device.startswith("cuda"):
            a @ b  # the first product pays for library start-up, which would end the doubling at 256
        _sync(device)
        t0 = now()
        a @ b  # warm-up, and the time of one product at this size
        _sync(device)
        one = now() - t0
        if n >= n_max or 8 * one * reps > budget_s:  # the next size costs 8x
            break
        n *= 2
    t0 = now()
    for _ in range(reps):
        a @ b
    _sync(device)
    return 2 * n**3 * reps / (now() - t0), n


def transition_flops(model: DFTransformer, batch: int, tokens: int) -> float:
    """FLOPs of one guided transition, counted from the shapes: forward (every matmul, attention
    included) plus the guidance backward to the input, which costs about one more forward."""
    w = model.out.in_features
    ff = model.blocks[0].ff1.out_features
    per_token = (model.token_dim + w // 2) * w + w * w + w * model.token_dim  # init MLP + output layer
    per_token += len(model.blocks) * (4 * w * w + 2 * w * ff + 2 * tokens * w)  # qkv, proj, FF, QK^T and AV
    return 2 * 2 * per_token * tokens * batch


def _sync(device: str) -> None:
    if device.startswith("cuda"):
        torch.cuda.synchronize()


def throughput(batches=(1, 25, 200), tokens=(11, 21, 51, 101), options=("fp32", "bf16"), width=128, layers=6,
               reps=3, device: str = "cpu", clock: str = "wall", rounds: int = 5, echo: bool = False) -> list[str]:
    """Guided transitions/s (jobs x transitions per second) and utilisation per option, side by side.

    Per cell every option is built and warmed up first, then timed in ``rounds`` interleaved
    rounds (option A, B, ..., A, B, ...) of ``reps`` transitions, at least 100 jobs' worth; a cell
    reports each option's median round, so a burst of load on a shared machine hits every option alike.
    Utilisation = counted FLOP/s over the peak of the option's dtype measured above (nanoGPT's MFU).
    A compiled option's first call (compilation) is left out of the timing, as a long run amortises it.
    ``clock="cpu"`` times with this process's CPU time: on a shared machine (other jobs on the
    cores) a one-thread run then measures the work per CPU second, which wall time cannot; it
    is wrong for more than one torch thread or a GPU, and is refused there.
    """
    if clock == "cpu" and (torch.get_num_threads() != 1 or not device.startswith("cpu")):
        raise SystemExit(f"bench_denoiser --throughput clock=cpu needs device=cpu and one torch thread "
                         f"(OMP_NUM_THREADS=1); here device={device}, threads={torch.get_num_threads()}")
    now = CLOCKS[clock]
    from fmctd_dist.config import DiffusionConfig
    from fmctd_dist.denoiser.runtime import runtime_model
    from fmctd_dist.diffusion.sampler import make_consts, transition

    consts = make_consts(DiffusionConfig(), device)
    dtypes = {"fp32": torch.float32, "bf16": torch.bfloat16}
    used = {OPTIONS[o][0] for o in options}
    # a GPU's peak needs far larger products than a CPU's (a 2048^3 product is a few microseconds on an H200)
    n_max = 16384 if device.startswith("cuda") else 2048
    measured = {d: peak_flops(dtypes[d], device, n_max=n_max, clock=clock) for d in dtypes if d in used}
    peaks = {d: f for d, (f, _) in measured.items()}
    peak_text = ", ".join(f"{d} {f / 1e9:,.0f} GFLOP/s at {n}^3" for d, (f, n) in measured.items())
    lines = [f"peak (square matmul): {peak_text}; "
             f"device {device}, torch threads {torch.get_num_threads()}, clock {clock}, median of {rounds} "
             f"interleaved rounds x {reps} transitions", "",
             "| tokens | batch | " + " | ".join(f"{o}: jobs/s (util.)" for o in options) + " | best / fp32 |",
             "|---|---|" + "---|" * (len(options) + 1)]
    if echo:
        print("\n".join(lines), flush=True)
    for t in tokens:
        for b in batches:
            x = torch.randn(b, t, 20, device=device)
            a = torch.full((b, t), 30, device=device)
            a[:, 0] = 0
            bl = (a - 1).clamp(min=0)
            scale = torch.full((b,), 1.0, device=device)
            s, g = torch.zeros(b, 2, device=device), torch.ones(b, 2, device=device)
            steps, bases = {}, {}
            for opt in options:
                precision, compiled = OPTIONS[opt]
                torch.manual_seed(0)
                bases[opt] = DFTransformer(20, t, width, layers, 4, 512).to(device).eval().requires_grad_(False)
                model = runtime_model(bases[opt], precision, compiled)
                steps[opt] = (lambda m: lambda: transition(m, consts, x, a, bl, scale, s, g, force_grad=True))(model)
                steps[opt]()  # warm-up (and compilation)
            times: dict[str, list[float]] = {o: [] for o in options}
            n = max(reps, 100 // b)  # small batches: enough transitions per round to time them
            for _ in range(rounds):
                for opt in options:
                    _sync(device)
                    t0 = now()
                    for _ in range(n):
                        steps[opt]()
                    _sync(device)
                    times[opt].append((now() - t0) / n)
            cells, rates = [], {}
            for opt in options:
                dt = float(np.median(times[opt]))
                rates[opt] = b / dt
                util = transition_flops(bases[opt], b, t) / dt / peaks[OPTIONS[opt][0]]
                cells.append(f"{b / dt:,.0f} ({100 * util:.0f}%)")
            best = max(rates, key=rates.get)
            ratio = f"{best} {rates[best] / rates['fp32']:.2f}x" if "fp32" in rates else "–"
            lines.append(f"| {t} | {b} | " + " | ".join(cells) + f" | {ratio} |")
            if echo:  # row by row, so a run stopped by a time limit keeps what it measured
                print(lines[-1], flush=True)
    return lines


def main(argv: list[str]) -> None:
    torch.manual_seed(0)
    if argv and argv[0] in ("-h", "--help"):
        print(__doc__)
        return
    missing = [a for a in argv if not a.startswith("--") and "=" not in a and not (Path(a) / "manifest.json").exists()]
    if missing:  # every other word is a mode (--cube) or a key=value (--throughput's, --cube's overrides)
        raise SystemExit(f"bench_denoiser: no checkpoint (manifest.json) at {', '.join(missing)}; give checkpoint "
                         "dirs such as checkpoints/pointmaze-medium-h5 (--help for the modes)")
    if argv and argv[0] == "--throughput":
        # --throughput [options=fp32,bf16,compiled,bf16+compiled] [batches=1,25,200] [tokens=11,21,51,101] [device=cpu]
        #   [clock=wall|cpu] [reps=3] [rounds=5] [layers=6] (layers: the model's depth; the dry runs use 1)
        kw = dict(a.split("=", 1) for a in argv[1:])
        unknown = set(kw) - {"options", "batches", "tokens", "device", "clock", "reps", "rounds", "layers"}
        if kw.get("clock", "wall") not in CLOCKS:
            raise SystemExit(f"bench_denoiser --throughput: clock={kw['clock']!r} is not one of {', '.join(CLOCKS)}")
        opts = tuple(kw.get("options", "fp32,bf16").split(","))
        if unknown or not set(opts) <= set(OPTIONS):
            raise SystemExit(f"bench_denoiser --throughput: unknown "
                             f"{sorted(unknown) or sorted(set(opts) - set(OPTIONS))}; "
                             f"options are {', '.join(OPTIONS)}")
        ints = lambda k, d: tuple(int(v) for v in kw.get(k, d).split(","))  # noqa: E731
        print("guided transitions/s (jobs x transitions per second) and utilisation, one run:")
        throughput(ints("batches", "1,25,200"), ints("tokens", "11,21,51,101"), opts, reps=int(kw.get("reps", 3)),
                   device=kw.get("device", "cpu"), clock=kw.get("clock", "wall"), rounds=int(kw.get("rounds", 5)),
                   layers=int(kw.get("layers", 6)), echo=True)
        return
    if argv and argv[0] == "--precision":
        for a in argv[1:]:
            print("\n".join(precision_lines(Path(a))) + "\n")
        return
    if argv and argv[0] == "--cube":
        words = [a for a in argv[1:] if "=" in a]  # key=value overrides for every checkpoint's config
        print("\n".join(cube_lines([Path(a) for a in argv[1:] if "=" not in a], words)))
        return
    # every shipped planning model (DF or Diffuser); other checkpoints (the ant expert) have no model_kind
    overrides = [a for a in argv if "." in a.partition("=")[0] and "=" in a]  # dotted: every checkpoint's config
    words = dict(a.split("=", 1) for a in argv if "=" in a and a not in overrides)
    if set(words) - {"samples"}:
        raise SystemExit(f"bench_denoiser: unknown {sorted(set(words) - {'samples'})}; "
                         "the quality mode takes samples=N and dotted config overrides "
                         "(e.g. diffusion.boundary_guidance=8)")
    per_task = int(words.get("samples", SAMPLES_PER_TASK))
    ckpts = [Path(a) for a in argv if "=" not in a] or sorted(
        p.parent for p in (REPO_ROOT / "checkpoints").glob("*/manifest.json")
        if "model_kind" in json.loads(p.read_text()))
    cubes = [c for c in ckpts
             if family(json.loads((c / "manifest.json").read_text())["config"]["env"]["name"]) == "cube"]
    ckpts = [c for c in ckpts if c not in cubes]
    if cubes:
        print("\n".join(cube_lines(cubes)) + "\n")
    print(f"{5 * per_task} unguided and {5 * per_task} guided plans per checkpoint (same noise for every checkpoint)")
    print("| checkpoint | steps | params | val loss | train h | unguided: no warp / in free cells / valid | "
          "guided: no warp / in free cells / valid / within 2.0 of goal | guided boundary / inside step |")
    print("|---|---|---|---|---|---|---|---|")
    for ckpt in ckpts:
        r = plan_quality(ckpt, checkpoint_config(ckpt, overrides), samples_per_task=per_task)
        print(f"| {r['checkpoint']} | {r['steps']} | {r['params']:,} | "
              f"{r['val_loss'] if r['val_loss'] is None else round(r['val_loss'], 4)} | {r['train_h']:.2f} | "
              f"{100 * r['unguided_no_warp']:.0f}% / {100 * r['unguided_in_free']:.1f}% / "
              f"{100 * r['unguided_valid']:.0f}% | "
              f"{100 * r['guided_no_warp']:.0f}% / {100 * r['guided_in_free']:.1f}% / {100 * r['guided_valid']:.0f}% / "
              f"{100 * r['guided_near_goal']:.0f}% | {r['guided_boundary_step']:.2f} / {r['guided_inside_step']:.2f} |")


if __name__ == "__main__":
    run(main)
