"""The planner's config: one dataclass per section (``env``, ``data``, ``model``, ...), each field with its
declared range, and the root :class:`Config` with the sizes derived from them."""

from __future__ import annotations

import dataclasses
import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from fmctd_dist.config.ranges import SEED, THREADS, spec
from fmctd_dist.config.repo import resolve_path
from fmctd_dist.registry import env_names, state_dim

UNET_PADDINGS = ("zeros", "replicate")
TASK_IDS = (1, 2, 3, 4, 5)
DEVICES = ("cpu", "cuda", "auto")
RUNNERS = ("local", "ray")
PLANNERS = ("mctd", "diffusion_forcing", "diffuser")
PROTOCOLS = ("fixed", "ogbench")
MODEL_KINDS = ("df", "diffuser")
BETA_SCHEDULES = ("linear", "cosine")  # same names as diffusion.schedule.BETA_SCHEDULES
# Recipe levers (issue 17); the first of each is the paper's recipe, the default.
MODEL_PARAMS = ("x0", "v", "v_offset")  # same names as diffusion.model.MODEL_PARAMS
MODEL_NORMS = ("post", "pre")
GUIDANCE_PATHS = ("input", "network")
LR_SCHEDULES = ("constant", "cosine", "wsd")
PRECISIONS = ("fp32", "bf16")
BOUNDARY_SPACES = ("token", "position")  # train.boundary_space: where the boundary step loss is measured
BUDGET_CLOCKS = ("wall", "cpu")


@dataclass
class EnvConfig:
    # pointmaze-{medium,large,giant} | antmaze-{...} | cube-{single,double,triple}
    name: str = spec("pointmaze-medium", choices=env_names)  # every registered family's envs
    # fixed: start/goal at cell centres (paper); ogbench: stock +-1 noise
    protocol: str = spec("fixed", choices=PROTOCOLS)
    max_steps: int = spec(500, gt=0, why="env steps of one episode (500 medium/large, 1000 giant)")
    horizon: int = spec(500, gt=0, why="planning horizon in env steps (500 medium/large, 1000 giant)")
    policy: str = ""  # antmaze: low-level policy dir ("" -> checkpoints/<env>-policy); unused for pointmaze
    # mazes (not the paper's): the robot follows a copy of each plan pushed this far off the walls
    # (families/maze/clearance.py); the rows keep the planner's own plan
    wall_clearance: float = spec(0.0, ge=0, le=2.0, why="world units the robot's copy of a plan keeps off a wall "
                                                        "face (a corridor's centre line is 2.0); 0 = off (the paper's)")
    # cube envs (docs/reference.md §13); 0 / [] = the method's setting (mazes leave them so)
    replan_every: int = spec(0, ge=0, why="env steps between replans for methods that replan; 0 = "
                                         "method.replan_every (cubes: 100 single, 200 double/triple)")
    warp_dense: float = spec(0.0, ge=0, why="cube value warp threshold at jump=1 (1.0), visual maze's on estimated "
                                             "positions; 0 = method.warp_threshold")
    warp_sparse: float = spec(0.0, ge=0, why="cube value warp threshold at jump>1 (2.0), visual maze's on estimated "
                                              "positions; 0 = method.warp_threshold")
    object_scales: list[float] = spec(factory=list, ge=0, each=True,
                                      why="guidance scales per unsolved object, e.g. [1, 2, 4] (cubes)")
    # cubes: the scripted pre-position also turns the open gripper to the target cube's yaw (mod 90 degrees,
    # the shortest turn, as OGBench's CubePlanOracle does), so the fingers close on faces, not corners.
    # false = the authors' rule (move, never turn); docs/results.md 12.5
    preposition_yaw: bool = False
    # cubes: a plan whose first frame puts any cube further than this from where it is counts as a warp
    # (such a plan sends the arm to an empty spot; docs/results.md 12.8). 0 = the authors' rules (only
    # the warp threshold applies to that first step)
    start_tolerance: float = spec(0.0, ge=0, why="cube value: largest first-frame offset of any cube from its "
                                                 "observed position (obs units); 0 = off (authors' rules)")


@dataclass
class DataConfig:
    root: str = "data"  # dataset cache dir (relative paths are under the repo root)
    seed: int = spec(0, ge=0, why=SEED)  # generator seed: same seed -> same bytes
    episodes: int = spec(1000, gt=0, why="OGBench navigate: 1000 (giant 500)")  # training episodes
    episode_steps: int = spec(1001, gt=1, why="OGBench: 1001 (giant 2001)")  # steps per episode
    noise: float = spec(0.5, ge=0, why="action noise std (pointmaze oracle 0.5, antmaze expert 0.2, "
                                        "cube plan oracle 0.1)")
    expert: str = "checkpoints/ant-expert"  # antmaze only: the ant expert dir whose actions make the data
    val_fraction: float = spec(0.1, ge=0, le=1, why="extra validation episodes as a fraction of data.episodes")
    train_window: int = spec(500, gt=0, why="raw env steps in one training window (= env.horizon)")
    # how the data is made, never what: any value writes the same bytes (episodes are independent)
    workers: int = spec(1, ge=1, why="processes that generate navigate episodes, e.g. the machine's cores")


@dataclass
class ModelConfig:
    kind: str = spec("df", choices=MODEL_KINDS)  # df: Diffusion Forcing transformer | diffuser: Janner's temporal U-Net
    frame_stack: int = spec(10, gt=0, why="frames per token (paper 10; the Diffuser 1)")
    width: int = spec(128, gt=0, why="d_model (paper 128), a multiple of model.heads")
    layers: int = spec(6, gt=0, why="transformer layers (paper 12)")  # 6 trains 2x faster on CPU, see docs/results.md
    heads: int = spec(4, gt=0, why="attention heads (paper 4)")
    ff: int = spec(512, gt=0, why="feed-forward width (paper 512)")
    unet_channels: list[int] = spec(factory=lambda: [32, 128, 256], gt=0, multiple_of=8, each=True, nonempty=True,
                                    why="kind=diffuser: widths per resolution, multiples of 8 (GroupNorm with 8 "
                                        "groups), e.g. [32, 128, 256]")
    unet_kernel: int = spec(5, gt=0, why="kind=diffuser: temporal conv kernel size, a positive odd number, e.g. 5")
    # kind=diffuser: how the convs pad the time axis. zeros (Janner's): the frames before the start
    # read as the normalised origin; replicate: as the start itself (see docs/results.md section 3.1)
    unet_padding: str = spec("zeros", choices=UNET_PADDINGS)
    # kind=diffuser: frames added at each end of the sequence before the U-Net (point reflections
    # 2 x_0 - x_i of the plan about its end frames, cropped after), so the plan's first and last
    # frames are computed like interior ones. 0 = Janner's U-Net (see docs/results.md section 3.1)
    unet_edge_frames: int = spec(0, ge=0, why="0 is Janner's U-Net, 16 reflects 16 frames at each end")
    # kind=df: what the network's output F means. x0 (paper): x0_hat = F; v: x0_hat = sqrt(ab) x_t -
    # sqrt(1-ab) F per number; v_offset: each token's frame mean (its offset) as v, its shape (frames
    # minus their mean) as x0. Trained with the same min-SNR x0 loss (see fmctd_dist.diffusion.model)
    param: str = spec("x0", choices=MODEL_PARAMS)
    norm: str = spec("post", choices=MODEL_NORMS)  # kind=df: post-LN blocks (paper) | pre-LN (+ a final LayerNorm)


@dataclass
class DiffusionConfig:
    timesteps: int = spec(1000, gt=1, why="training diffusion steps (paper 1000)")
    beta_schedule: str = spec("linear", choices=BETA_SCHEDULES)  # linear (Diffusion Forcing) | cosine (Diffuser)
    levels: int = spec(50, gt=0, why="DDIM sampling levels (paper 50)")
    beta_start: float = spec(1e-4, gt=0, lt=1, why="paper 1e-4")
    beta_end: float = spec(0.02, gt=0, lt=1, why="paper 0.02")
    stabilization: int = spec(10, ge=1, why="clean tokens are fed as timestep stabilization-1 (paper 10)")
    snr_clip: float = spec(5.0, gt=0, why="min-SNR loss weight clip (paper 5)")
    clip_noise: float = spec(20.0, gt=0, why="initial noise clipped to +-clip_noise (paper 20)")
    # Goal guidance's gradient w.r.t. the noisy input: input (the authors'): through the whole x0
    # estimate; network: through the network branch only, model.param's skip path held constant
    # (the same as input for model.param=x0, which has none)
    guidance_path: str = spec("input", choices=GUIDANCE_PATHS)
    # Boundary-continuity guidance (our lever, 0 = the authors' reward): guided jobs also pull each
    # token boundary's step toward the step before it (sampler.goal_reward), against the jumps at
    # token boundaries our models make (docs/results.md §4)
    boundary_guidance: float = spec(0.0, ge=0, why="weight of the boundary term in the guidance reward; 0 = off")
    # How denoisers run the network (issue 22): fp32 (reference) | bf16 (weights stored bf16, autocast);
    # compile: torch.compile with one graph per micro-batch shape. Off until measured (docs/results.md 6).
    precision: str = spec("fp32", choices=PRECISIONS)
    compile: bool = False


@dataclass
class TrainConfig:
    max_steps: int = spec(8000, gt=0, why="optimiser steps (paper 200k at batch 1024 on GPU)")
    batch_size: int = spec(256, gt=0, why="windows per step (paper 1024)")
    lr: float = spec(5e-4, gt=0, lt=1, why="AdamW learning rate (paper 5e-4)")
    weight_decay: float = spec(1e-4, ge=0, why="AdamW weight decay (paper 1e-4)")
    warmup: int = spec(1000, ge=0, why="linear warm-up steps; 0 = none")
    ema_decay: float = spec(0.999, ge=0, lt=1, why="shipped weights are an EMA of the trained ones; 0 = off")
    ckpt_every: int = spec(500, gt=0, why="steps between resumable checkpoints")
    val_every: int = spec(1000, ge=0, why="steps between validation losses; 0 = none")
    val_batches: int = spec(8, gt=0, why="batches per validation-loss evaluation")
    seed: int = spec(0, ge=0, why=SEED)
    out: str = ""  # checkpoint dir; "" -> runs/<env>-h<jump> (ship with train.out=checkpoints/<env>-h<jump>)
    threads: int = spec(0, ge=0, why=THREADS)  # torch intra-op threads
    # A checkpoint dir whose weights start a fresh run (fine-tuning, e.g. an AntMaze model from the
    # PointMaze one of the same maze): same architecture, any env / horizon. Recorded in the manifest;
    # ignored when train.out already holds a run to resume.
    init_from: str = ""
    # Diffuser only (Janner et al.'s ``loss_discount``): plan frame f is weighted discount**f in the
    # x0 loss (weights normalised to mean 1). 1.0 = uniform, the paper's and Janner's maze setting.
    loss_discount: float = spec(1.0, gt=0, le=1, why="plan frame f is weighted discount**f (1.0 = uniform, the "
                                                      "paper's setting)")
    # Training windows drawn with weight count(start's 1x1 grid cell)**-start_balance (0 = uniform,
    # the paper's). Leaves p(plan | start) unchanged; see fmctd_dist.data.windows.start_balance_cdf.
    start_balance: float = spec(0.0, ge=0, le=1, why="windows are drawn with weight count(start cell)**-start_balance "
                                                     "(0 = uniform, the paper's; 1 = every start cell alike)")
    # Recipe lever against the plans' jumps at token boundaries (results §4): an extra loss on the step
    # across each token boundary (last frame of token k -> first frame of token k+1, the context token
    # included), predicted against true, min-SNR-weighted by the noisier of the two tokens. The
    # conditional mean still minimises it, so it re-weights toward tokens' relative offsets without
    # changing the optimum. 0 = off (the paper's).
    boundary_weight: float = spec(0.0, ge=0, why="weight of the token-boundary step loss (0 = off, the paper's)")
    # Where that step is measured. token: in the model's normalised frame units. position: through the
    # dataset's position readout (data module's ``position_readout``; maze states: x, y; visual latents: the
    # frozen position estimator), in standardised world units. A visual latent moves mostly in directions the
    # estimator ignores (frame-to-frame jitter), so a latent step that looks ordinary can be a 7-unit jump
    # in position (results 13.4, session 30): the position space weights the directions that matter.
    boundary_space: str = spec("token", choices=BOUNDARY_SPACES)
    # A loss on the position of each token's two end frames, read the same way (readout of the prediction
    # vs of the truth, min-SNR-weighted like the token loss): the token loss weighs a latent's
    # position-blind jitter as much as its position. 0 = off (the paper's).
    position_weight: float = spec(0.0, ge=0, why="weight of the position loss on each token's end frames through the "
                                                 "data's position readout (0 = off, the paper's)")
    # Recipe lever against plans through walls (the lines below the paper): the mean depth inside the maze's
    # walls of every predicted frame (the data module's ``wall_depth``; maze data only), each noise level alike.
    # Zero on every data window. 0 = off (the paper's).
    wall_weight: float = spec(0.0, ge=0, why="weight of the loss on predicted frames' depth inside the maze's walls "
                                             "(0 = off, the paper's)")
    # Recipe lever against the plans' first-step jump (results §4, session 21): the sampler always feeds
    # the context token clean (timestep diffusion.stabilization - 1, scaled, no noise), but the paper's
    # training noises it at a random timestep (half the time in [0, 250), else anywhere), so that exact
    # input is rare in training. With probability clean_context a window's context is fed exactly as the
    # sampler feeds it. 0 = off (the paper's).
    clean_context: float = spec(0.0, ge=0, le=1, why="share of training windows whose context token is fed as the "
                                                     "sampler feeds it (0 = off, the paper's)")
    # constant (paper): warm-up then train.lr; cosine: warm-up then cosine decay to 0 at the run's end
    # (train.max_steps, or train.time_budget_s of recorded wall time if that comes first); wsd
    # (warm-up, stable, decay): constant, then linear to 0 over the last train.decay_steps steps before
    # train.max_steps. Since only the tail depends on max_steps, a constant-LR run can be resumed as a
    # wsd run with a nearer max_steps: it anneals from its own optimiser state.
    lr_schedule: str = spec("constant", choices=LR_SCHEDULES)
    decay_steps: int = spec(0, ge=0, why="lr_schedule=wsd: the LR falls linearly to 0 over the last decay_steps "
                                         "steps before train.max_steps (0 = the last 20%)")
    precision: str = spec("fp32", choices=PRECISIONS)  # fp32 (paper) | bf16: autocast for the training step
    time_budget_s: float = spec(0.0, ge=0, why="stop (with a checkpoint) once the run's recorded wall time reaches "
                                                "this many seconds, so recipe arms get equal wall-clock; 0 = none")
    # What time_budget_s counts: wall seconds, or this process's CPU seconds (fair between recipe arms
    # trained one after another while other jobs load the machine; use with train.threads=1)
    budget_clock: str = spec("wall", choices=BUDGET_CLOCKS)
    # A copy of the shipped (EMA) weights every this many budget-clock seconds, at the next resumable
    # checkpoint, under <train.out>/snapshots/: what quality-vs-training-time curves are measured on
    snapshot_every_s: float = spec(0.0, ge=0, why="seconds (train.budget_clock) between weight snapshots kept "
                                                  "under <train.out>/snapshots/; 0 = none")


@dataclass
class MethodConfig:
    name: str = "fast-mctd"
    planner: str = spec("mctd", choices=PLANNERS)  # mctd | diffusion_forcing | diffuser
    parallel: int = spec(200, gt=0, why="K: rollouts per iteration (1 = sequential MCTD, paper 200)")
    virtual_weight: float = spec(1.0, ge=0, why="w: weight of virtual visits in UCT (paper 1)")
    redundancy_aware: bool = True  # each empty slot claimed at most once per batch
    leaf_parallel: bool = False  # a selected child gets |children| virtual visits
    guidance_scales: list[float] = spec(factory=lambda: [0.0, 0.1, 0.5, 1.0, 2.0], ge=0, each=True, nonempty=True,
                                        why="the tree's guidance choices, e.g. [0, 0.1, 0.5, 1, 2]")
    budget: int = spec(500, gt=0, why="expansion budget in expanded nodes (paper 500)")
    segment_transitions: int = spec(20, gt=0, why="DDIM transitions per tree depth")
    sim_skip: int = spec(10, gt=0, why="jumpy simulation: rows skipped per transition (paper 10)")
    warp_threshold: float = spec(2.0, gt=0, why="max plan step in world units before a plan is a warp "
                                                "(1.0 dense, 2.0 at H=5)")
    goal_radius: float = spec(2.0, gt=0, why="value: a plan reaches the goal within this radius (paper 2)")
    # Not the paper's (its value tests warps only): value 0 also for a plan whose path crosses a wall
    # before it reaches the goal, tested at 10 points per step on the maze's cells. Smooth models
    # pass the warp test through walls (results §4, session 23-24); point / ant mazes only.
    wall_test: bool = False
    # Not the paper's either: a guidance term pushing plan frames out of wall cells (families/maze/wall_guide.py);
    # the value stays the authors'. Point / ant mazes only.
    wall_guidance: float = spec(0.0, ge=0, why="weight of the wall term in the guidance reward; 0 = off (the paper's)")
    wall_margin: float = spec(0.5, ge=0, le=2.0, why="world units the wall term keeps plan frames off a wall face")
    bad_plan_tries: int = spec(10, ge=1, why="re-samples of plans that barely move")
    bad_plan_step: float = spec(0.1, ge=0, why="a plan barely moves if every step is below this")
    uct_c: float = spec(1.4142135623730951, ge=0, why="UCT exploration constant (sqrt 2)")
    early_stop: bool = True  # stop when a new node's own plan reaches the goal
    replan_every: int = spec(0, ge=0, why="env steps between replans; 0 = plan once (open loop)")
    guidance_scale: float = spec(2.0, ge=0, why="fixed scale for planners without search")
    # Diffuser only: RePaint resampling U (each level re-visited U times; 1 = plain DDIM, the paper's)
    resample: int = spec(1, ge=1, why="1 = plain DDIM (the paper's), 10 = RePaint x10")


@dataclass
class EvalConfig:
    runner: str = spec("ray", choices=RUNNERS)  # ray (local cluster, or the running one) | local (no Ray, one process)
    tasks: list[int] = spec(factory=lambda: [1, 2, 3, 4, 5], ge=1, le=5, each=True, nonempty=True,
                            why="a list drawn from [1, 2, 3, 4, 5]")
    seeds: list[int] = spec(factory=lambda: list(range(10)), ge=0, each=True, nonempty=True,
                            why="a list of non-negative integers, e.g. [0,1]")
    out: str = "results"  # results root; rows go to <out>/<run>/<method>/<env>/...
    run: str = "default"
    episode_time_limit: float = spec(0.0, ge=0, why="seconds of planning per episode; 0 = none")
    # torch threads of an in-process denoiser (runner=local, bench_speed); 0 = torch default.
    # Set 1 when other jobs share the cores: 2 spinning threads on a busy 2-core machine run 10x slower.
    threads: int = spec(0, ge=0, why=THREADS)
    # episodes planned at once, their trees' denoiser jobs pooled into shared micro-batches (rows do not change)
    in_flight: int = spec(1, ge=1, why="episodes in flight per runner (local) or per denoiser actor (ray); 1 = one")


@dataclass
class RayConfig:
    address: str = ""  # "" -> join a running cluster if there is one, else start local
    # 0 = auto: one DenoiserActor per GPU (ray.num_gpus each) or per ray.num_cpus CPUs of the cluster
    denoiser_actors: int = spec(0, ge=0, why="DenoiserActors in the pool; 0 = one per GPU or CPU the cluster has")
    env_actors: int = spec(0, ge=0, why="EnvActors, one episode each at a time; 0 = as many as denoiser actors")
    micro_batch: int = spec(8, gt=0, why="M: jobs per denoiser call (fixed shapes -> determinism); raise on GPUs")
    num_gpus: float = spec(0.0, ge=0, why="GPUs per denoiser actor (needs device=cuda)")
    num_cpus: float = spec(1.0, ge=0, why="CPUs per denoiser actor")
    call_timeout_s: float = spec(300.0, gt=0, why="a call slower than this per micro-batch it holds is re-routed")
    max_restarts: int = spec(3, ge=0, why="restarts per denoiser actor, and re-runs per episode whose env actor or "
                                         "driver died or timed out; 0 = neither (a dead actor's micro-batches are "
                                         "still re-routed)")
    # The longest episode recorded on our 2-core CPU took 358 s (MCTD-family on PointMaze-giant): an hour is
    # 10x that, so only a hung env actor or driver (alive, never answering) reaches it.
    episode_timeout_s: float = spec(3600.0, gt=0, why="an episode still running after this long is killed and re-run "
                                                      "on a new env actor + driver; raise it for slower episodes")


@dataclass
class VisualConfig:
    """Visual PointMaze (issue 21): how frames are rendered, and which of the point maze's frames are."""

    # MuJoCo's shadow map side in texels. 4096 (MuJoCo's default) draws OGBench's frames exactly and
    # is the reference; 1024 renders 3-5x faster on CPU Mesa with ~0.3% of pixels off (shadow edges),
    # bounded by tests/test_visual.py. Frames for training and for the env must use the same value.
    shadowsize: int = spec(1024, ge=0, why="1024 (default, fast); 4096 = MuJoCo's default, the reference frames")
    frames: int = spec(20000, gt=0, why="images in the VAE's seeded subset of the train split's frames")
    frames_seed: int = spec(0, ge=0, why=SEED)  # which frames the subset holds: same seed -> same bytes
    # Train episodes whose every frame is rendered and encoded for the planner's latent data, a
    # seeded subset (recorded in the latent manifest); 0 = all of data.episodes
    episodes: int = spec(100, ge=0, why="seeded subset of train episodes for the latent data; 0 = all")
    # Plan [z, x, y] frames: each latent with the position estimator's reading of it (families/visual/dataset.py),
    # so the diffusion loss sees positions and guidance / value read the plan's own (x, y) (our variant:
    # the paper plans latents only). A planner checkpoint is trained for one choice.
    plan_xy: bool = False


@dataclass
class Config:
    env: EnvConfig = field(default_factory=EnvConfig)
    data: DataConfig = field(default_factory=DataConfig)
    model: ModelConfig = field(default_factory=ModelConfig)
    diffusion: DiffusionConfig = field(default_factory=DiffusionConfig)
    train: TrainConfig = field(default_factory=TrainConfig)
    method: MethodConfig = field(default_factory=MethodConfig)
    eval: EvalConfig = field(default_factory=EvalConfig)
    ray: RayConfig = field(default_factory=RayConfig)
    visual: VisualConfig = field(default_factory=VisualConfig)
    jump: int = spec(1, gt=0, why="H: plan on trajectories subsampled every H env steps (S-MCTD: 5)")
    device: str = spec("cpu", choices=DEVICES)  # cpu | cuda | auto
    checkpoint: str = ""  # checkpoint dir; "" -> checkpoints/<env>-h<jump> (model.kind=diffuser: <env>-diffuser)
    seed: int = spec(0, ge=0, why=SEED)  # planning seed offset (episode seeds come from eval.seeds)

    # ---- derived quantities (read-only helpers) ----
    @property
    def plan_frames(self) -> int:
        """Frames in one plan (excluding the start frame)."""
        return self.env.horizon // self.jump

    @property
    def plan_tokens(self) -> int:
        """P: plan tokens, excluding the context token."""
        return self.plan_frames // self.model.frame_stack

    @property
    def n_tokens(self) -> int:
        """Tokens the model sees: context + P plan tokens."""
        return self.plan_tokens + 1

    @property
    def frame_dim(self) -> int:
        """Numbers per plan frame: the env family's planner state (maze x, y: 2; cube xyz: 3 per cube; a
        visual latent: 8, or 10 with visual.plan_xy's estimated x, y)."""
        return state_dim(self.env.name) + (2 if self.visual.plan_xy else 0)

    @property
    def token_dim(self) -> int:
        return self.frame_dim * self.model.frame_stack

    @property
    def run_name(self) -> str:
        """<env>-h<jump> (Diffusion Forcing models; <env>-h<jump>-xy with visual.plan_xy) or <env>-diffuser:
        the default checkpoint / run dir name, so each planner variant is one config word away."""
        if self.model.kind == "diffuser":
            return f"{self.env.name}-diffuser"
        return f"{self.env.name}-h{self.jump}" + ("-xy" if self.visual.plan_xy else "")

    def checkpoint_dir(self) -> Path:
        return resolve_path(self.checkpoint or f"checkpoints/{self.run_name}")

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    def digest(self) -> str:
        """Short hash of the whole config (recorded with every result row)."""
        blob = json.dumps(self.to_dict(), sort_keys=True).encode()
        return hashlib.sha256(blob).hexdigest()[:16]
