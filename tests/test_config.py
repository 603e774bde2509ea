"""Config loading: groups, overrides, aliases, and one clear ConfigError per bad field."""

import re

import pytest

from fmctd_dist.config import Config, config_from_dict, load_config
from fmctd_dist.errors import ConfigError


def test_groups_and_overrides():
    cfg = load_config(["env=pointmaze-giant", "method=p-mctd", "method.parallel=50", "tasks=[2,3]", "runner=ray"])
    assert ((cfg.env.name, cfg.env.horizon, cfg.data.episodes, cfg.data.episode_steps)
            == ("pointmaze-giant", 1000, 500, 2001))
    assert (cfg.method.name, cfg.method.parallel, cfg.jump) == ("p-mctd", 50, 1)
    assert cfg.eval.tasks == [2, 3] and cfg.eval.runner == "ray"
    assert cfg.plan_tokens == 100 and cfg.n_tokens == 101


def test_fast_mctd_is_sparse_and_parallel():
    cfg = load_config([])
    assert (cfg.method.name, cfg.jump, cfg.method.parallel, cfg.method.warp_threshold) == ("fast-mctd", 5, 200, 2.0)
    assert cfg.plan_tokens == 10 and cfg.checkpoint_dir().name == "pointmaze-medium-h5"


def test_round_trip_dict():
    cfg = load_config(["env=pointmaze-large", "jump=5", "method=s-mctd"])
    assert config_from_dict(cfg.to_dict()) == cfg
    assert cfg.digest() == config_from_dict(cfg.to_dict()).digest()
    assert isinstance(cfg, Config)


@pytest.mark.parametrize(
    "args, field",
    [
        (["env=pointmaze-gaint"], "env"),  # unknown env name, with suggestion
        (["method=fast-mcdt"], "method"),  # unknown method
        (["method.parralel=3"], "method.parralel"),  # unknown key
        (["train.max_steps=abc"], "train.max_steps"),  # wrong type
        (["env.horizon=505"], "env.horizon"),  # not divisible by jump x frame_stack
        (["env=pointmaze-medium", "jump=3"], "env.horizon"),  # 500 % 30
        (["seeds=[-1]"], "eval.seeds"),  # negative seed
        (["tasks=[6]"], "eval.tasks"),  # bad task id
        (["device=gpu"], "device"),  # unknown device
        (["env.protocol=noisy"], "env.protocol"),
        (["data.episode_steps=300"], "data.episode_steps"),  # window longer than episodes
        (["method.guidance_scales=[]"], "method.guidance_scales"),
        (["ray.denoiser_actors=-1"], "ray.denoiser_actors"),
        (["method.planner=beam"], "method.planner"),
        (["horizon"], "key=value"),
        (["data.train_window=450", "env.horizon=500"], "data.train_window"),
        (["eval.threads=-1"], "eval.threads"),
        (["train.threads=-2"], "train.threads"),
    ],
)
def test_bad_config_names_the_field(args, field):
    with pytest.raises(ConfigError) as e:
        load_config(args)
    assert field in str(e.value)


def test_did_you_mean():
    with pytest.raises(ConfigError, match="did you mean 'pointmaze-giant'"):
        load_config(["env=pointmaze-gaint"])
    with pytest.raises(ConfigError, match="did you mean 'method.parallel'"):
        load_config(["method.parralel=3"])


@pytest.mark.parametrize(
    "args, field",
    [
        (["env=pointmaze-medium", "env.start_tolerance=0.5"], "env.start_tolerance=0.5 is read by cube envs only"),
        (["env=antmaze-large", "env.preposition_yaw=true"], "env.preposition_yaw=True is read by cube envs only"),
        (["env=pointmaze-giant", "env.policy=checkpoints/cube-single-policy"], "env.policy="),
        (["env=visual-pointmaze-medium", "env.replan_every=50"], "env.replan_every=50"),
        (["env=pointmaze-large", "env.warp_sparse=8.0"], "env.warp_sparse=8.0 is read by cube / visual-pointmaze"),
    ],
)
def test_env_field_of_another_family_is_refused(args, field):
    """A family-specific env field set on an env that never reads it would be silently unused."""
    with pytest.raises(ConfigError, match=re.escape(field)):
        load_config(args)


def test_env_fields_their_family_reads_load():
    assert load_config(["env=cube-triple", "env.start_tolerance=0.5"]).env.start_tolerance == 0.5
    assert load_config(["env=antmaze-medium", "env.policy=x"]).env.policy == "x"
    assert load_config(["env=visual-pointmaze-large", "env.warp_sparse=8.0"]).env.warp_sparse == 8.0


def test_wall_test_is_for_point_and_ant_mazes_only():
    from fmctd_dist.config import load_config
    from fmctd_dist.errors import ConfigError

    assert load_config(["env=antmaze-large", "method.wall_test=true"]).method.wall_test
    with pytest.raises(ConfigError, match="method.wall_test"):
        load_config(["env=cube-single", "method.wall_test=true"])


def _roots():
    """Every config root's loader, with a float field under its own prefix that must be > 0."""
    from fmctd_dist.control.policy.config import load_policy_args
    from fmctd_dist.families.maze.expert.config import load_expert_config
    from fmctd_dist.families.visual.config import load_parts_args

    return {"planner": (load_config, "train.lr"), "ant expert": (load_expert_config, "sac.lr"),
            "visual parts": (lambda words: load_parts_args(["part=vae", *words]), "vae.lr"),
            "policy": (load_policy_args, "policy.lr")}


@pytest.mark.parametrize("root", ["planner", "ant expert", "visual parts", "policy"])
def test_every_config_root_goes_through_the_one_loader(root):
    """The side roots parse, merge and range-check their words as the planner's config does: same error shapes."""
    load, key = _roots()[root]
    bad = {(key,): f"override '{key}' is not key=value; e.g. ",
           (f"{key}r=1",): f"unknown config key '{key}r' (did you mean '{key}'?)",
           (f"{key}=0.1", f"{key}=0.2"): f"{key} is given twice ({key}=0.1 and {key}=0.2); give it once",
           (f"{key}=abc",): f"override {key}=abc: {key}: Value 'abc' of type 'str' could not be converted to Float",
           (f"{key}=0.0",): f"{key}=0.0 must be > 0",
           (f"{key}=nan",): f"{key}=nan must be > 0"}
    for words, start in bad.items():
        with pytest.raises(ConfigError) as e:
            load(list(words))
        assert str(e.value).startswith(start), (words, str(e.value))
