"""Teacher demonstrations: returns per episode, the file's spec check, cloning, and a real (tiny) collection."""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path

import numpy as np
import pytest

from st_sim.apps.navigation.demonstrations import (
    ARRAYS,
    FORMAT,
    DemoFileError,
    Demos,
    DemoSpec,
    behaviour_clone,
    load_or_collect,
    save,
)
from st_sim.apps.navigation.features import FeatureConfig


def hand_made(steps: int = 6, seed: int = 0) -> Demos:
    rng = np.random.default_rng(seed)
    sizes = FeatureConfig(True).size, FeatureConfig(False).size
    return Demos(rng.normal(size=(steps, sizes[0])).astype(np.float32),
                 rng.normal(size=(steps, sizes[1])).astype(np.float32),
                 rng.uniform(-1, 1, (steps, 2)).astype(np.float32), np.ones(steps, np.float32),
                 np.arange(steps) % 3 == 2, wall_time_s=1.5)


def test_returns_restart_at_every_episode_end() -> None:
    demos = hand_made()  # two episodes of three steps, reward 1 per step
    returns = demos.returns(gamma=0.5)
    np.testing.assert_allclose(returns, [1.75, 1.5, 1.0, 1.75, 1.5, 1.0])


def test_a_file_with_another_spec_or_damaged_bytes_is_refused_by_name(tmp_path: Path) -> None:
    path = tmp_path / "demos.npz"
    save(hand_made(), DemoSpec(steps=6), path)
    loaded = load_or_collect(DemoSpec(steps=6), path)
    np.testing.assert_array_equal(loaded.actions, hand_made().actions)
    assert loaded.wall_time_s == 1.5
    with pytest.raises(DemoFileError, match=r"demos\.npz: collected with .*'steps': 6"):
        load_or_collect(DemoSpec(steps=7), path)
    path.write_bytes(path.read_bytes()[:100])
    with pytest.raises(DemoFileError, match=r"demos\.npz: not a readable demonstrations file"):
        load_or_collect(DemoSpec(steps=6), path)


def test_a_file_written_before_a_spec_field_existed_reads_as_that_fields_default(tmp_path: Path) -> None:
    path, demos = tmp_path / "old.npz", hand_made()
    old_spec = {k: v for k, v in {"format": FORMAT, **asdict(DemoSpec(steps=6))}.items() if k != "student"}
    np.savez(path, spec=json.dumps(old_spec), **{name: getattr(demos, name) for name in ARRAYS}, wall_time_s=1.0)
    np.testing.assert_array_equal(load_or_collect(DemoSpec(steps=6), path).actions, demos.actions)
    with pytest.raises(DemoFileError, match="collected with"):
        load_or_collect(DemoSpec(steps=6, student="clone.pt"), path)


@pytest.mark.parametrize("use_predictions", [True, False])
def test_cloning_fits_the_teacher_actions_and_returns(use_predictions: bool) -> None:
    from st_sim.apps.navigation.ppo import build_policy

    demos = hand_made(steps=512)
    features = demos.features(use_predictions)
    teacher = np.tanh(features[:, :2]).astype(np.float32)  # actions: a smooth function of the features
    rewards = np.tanh(features[:, 2]).astype(np.float32)  # one-step episodes: the return is the reward
    demos = Demos(demos.features_with, demos.features_without, teacher, rewards, np.ones(512, bool))
    policy = build_policy(FeatureConfig(use_predictions), [64, 64])
    fit = behaviour_clone(policy, demos, use_predictions, gamma=0.9, epochs=40, seed=0)
    assert fit["action_mse"] < 0.1 * float(np.mean(np.sum(teacher ** 2, axis=1))), fit  # vs a zero policy
    assert fit["value_mse"] < 0.1 * float(np.mean(rewards ** 2)), fit


def test_collect_runs_the_teacher_and_keeps_both_feature_sets(tmp_path: Path) -> None:
    spec = DemoSpec(steps=12, workers=1)
    demos = load_or_collect(spec, tmp_path / "demos.npz", progress=False)
    assert demos.features_with.shape == (12, FeatureConfig(True).size)
    assert demos.features_without.shape == (12, FeatureConfig(False).size)
    assert np.isfinite(demos.features_with).all() and np.isfinite(demos.rewards).all()
    assert np.abs(demos.actions).max() <= 1.0 and demos.episode_ends[-1]
    # the features without predictions are the ones with them, minus the prediction columns
    np.testing.assert_array_equal(demos.features_with[:, :19], demos.features_without[:, :19])
    assert demos.wall_time_s > 0


@pytest.mark.parametrize("demo_steps", [0, 24])
def test_train_ppo_writes_a_loadable_policy_curve_and_record(tmp_path: Path, demo_steps: int) -> None:
    """The training script end to end on a tiny budget (256 env steps), from scratch and from demonstrations."""
    from st_sim.apps.navigation.ppo import load_policy
    from st_sim.apps.navigation.train_ppo import main, parse_args

    cfg = parse_args(["--no-predictions", "--timesteps", "256", "--num-envs", "2", "--demo-steps", str(demo_steps),
                      "--demos", str(tmp_path / "demos.npz"), "--out", str(tmp_path / "run"), "--quiet",
                      *(["--sensor-range", "inf"] if demo_steps else ["--tensorboard", str(tmp_path / "tb")])])
    policy_path = main(cfg)
    policy, features = load_policy(policy_path)
    assert not features.use_predictions and policy.observation_space.shape == (features.size,)
    record = json.loads((tmp_path / "run" / "training.json").read_text())
    assert record["config"]["timesteps"] == 256 and (tmp_path / "run" / "curve.png").stat().st_size > 0
    assert (record["cloning"] is None) == (demo_steps == 0)
    if demo_steps:
        assert record["cloning"]["rounds"][0]["action_mse"] >= 0 and (tmp_path / "demos.npz").exists()
    else:  # stable-baselines3's own logger wrote TensorBoard events
        assert any(path.stat().st_size > 0 for path in (tmp_path / "tb").rglob("events.out.tfevents.*"))


def test_dagger_rounds_let_the_clone_drive_and_the_teacher_label(tmp_path: Path) -> None:
    """Each round adds the clone's own steps, labelled by the teacher, to the labels the next fit sees; the clone's
    episodes are its own (they differ from the teacher's on the same seeds)."""
    from st_sim.apps.navigation.train_ppo import DAGGER_SEED_STRIDE, TrainConfig, main, parse_args

    out = tmp_path / "run"
    args = ["--num-envs", "2", "--demo-steps", "24", "--dagger-rounds", "2", "--dagger-steps", "12", "--bc-epochs",
            "2", "--sensor-range", "inf", "--closest-approach", "--demos", str(tmp_path / "demos.npz"), "--out",
            str(out), "--quiet"]
    main(parse_args(["--timesteps", "0", *args]))
    rounds = json.loads((out / "training.json").read_text())["cloning"]["rounds"]
    assert [r["labelled_steps"] for r in rounds] == [24, 36, 48]
    # PPO then continues from the clone, and its record keeps the cloning's
    main(parse_args(["--timesteps", "64", *args]))
    record = json.loads((out / "training.json").read_text())
    assert record["resumed_from"] == 0 and record["cloning"]["rounds"] == rounds
    assert record["final"]["timesteps"] >= 64
    reward = asdict(TrainConfig().reward)  # the training reward: the teacher's returns are under it
    teacher = load_or_collect(DemoSpec(steps=24, closest_approach=True, reward=reward), tmp_path / "demos.npz")
    for round_ in (1, 2):
        spec = DemoSpec(steps=12, seed=DemoSpec().seed + DAGGER_SEED_STRIDE * round_, closest_approach=True,
                        student=str(out / f"dagger-{round_}.pt"), reward=reward)
        labelled = load_or_collect(spec, out / f"dagger-{round_}.npz")
        assert labelled.features_with.shape == (12, FeatureConfig(True, closest_approach=True).size)
        assert np.abs(labelled.actions).max() <= 1.0
        assert not np.array_equal(labelled.features_with, teacher.features_with[:12])


def test_a_student_that_reads_other_features_is_refused_by_file(tmp_path: Path) -> None:
    from st_sim.apps.navigation.demonstrations import load_student
    from st_sim.apps.navigation.ppo import build_policy, save_policy

    cfg = FeatureConfig(True, closest_approach=False)
    save_policy(build_policy(cfg, [8]), cfg, [8], tmp_path / "student.pt")
    with pytest.raises(DemoFileError, match=r"student\.pt: the student reads .* but the demonstrations hold"):
        load_student(DemoSpec(closest_approach=True, student=str(tmp_path / "student.pt")))
    assert load_student(DemoSpec(closest_approach=False, student=str(tmp_path / "student.pt")))[1] == cfg


@pytest.mark.parametrize(("flag", "value"), [("--timesteps", "-1"), ("--num-envs", "0"), ("--demo-steps", "-1"),
                                             ("--timesteps", "many"), ("--sensor-range", "nan"), ("--minutes", "0"),
                                             ("--demo-steps", "100"), ("--dagger-rounds", "1"),
                                             ("--log-std-init", "nan")])
def test_train_ppo_refuses_bad_budgets_by_flag(flag: str, value: str, capsys: pytest.CaptureFixture) -> None:
    from st_sim.apps.navigation.train_ppo import parse_args

    with pytest.raises(SystemExit):
        parse_args([flag, value])
    assert flag.lstrip("-") in capsys.readouterr().err.replace("_", "-")


def test_tensorboard_logging_without_tensorboard_installed_is_refused_before_any_work(
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture) -> None:
    from st_sim.apps.navigation import train_ppo

    real = train_ppo.util.find_spec
    monkeypatch.setattr(train_ppo.util, "find_spec", lambda name: None if name == "tensorboard" else real(name))
    with pytest.raises(SystemExit):
        train_ppo.parse_args(["--tensorboard", "tb"])
    assert "TensorBoard is not installed; pip install -e '.[tensorboard]'" in capsys.readouterr().err


def test_an_empty_collection_is_refused_before_any_work() -> None:
    from st_sim.apps.navigation.demonstrations import collect

    with pytest.raises(ValueError, match=r"DemoSpec.steps=0"):
        collect(DemoSpec(steps=0))


def test_a_stopped_training_continues_from_its_saved_state(tmp_path: Path) -> None:
    """A finished 256-step run, started again with a 512-step budget, continues at 256 (its wall time counted on from
    the first segment's); the finished run started again with a budget it reached stands as it was; other settings
    and smaller budgets refuse."""
    from st_sim.apps.navigation.train_ppo import main, parse_args

    args = ["--no-predictions", "--num-envs", "2", "--demo-steps", "0", "--save-every", "1", "--out",
            str(tmp_path / "run"), "--quiet"]
    main(parse_args([*args, "--timesteps", "256"]))
    first = json.loads((tmp_path / "run" / "curve.json").read_text())
    main(parse_args([*args, "--timesteps", "512"]))
    record = json.loads((tmp_path / "run" / "training.json").read_text())
    curve = json.loads((tmp_path / "run" / "curve.json").read_text())
    assert record["resumed_from"] == 256 and curve[:len(first)] == first
    assert curve[-1]["timesteps"] == 512
    walls = [point["wall_s"] for point in curve]
    assert walls == sorted(walls) and walls[len(first)] >= first[-1]["wall_s"], "the second segment restarted the clock"
    assert record["wall_time_s"] >= first[-1]["wall_s"]
    finished = (tmp_path / "run" / "training.json").read_bytes()
    for budget in ("512", "300"):  # the same budget again, or one its last rollout passed: nothing moves
        main(parse_args([*args, "--timesteps", budget]))
        assert (tmp_path / "run" / "training.json").read_bytes() == finished
    with pytest.raises(ValueError, match=r"resume\.zip: saved by a run with other settings \(seed\)"):
        main(parse_args([*args, "--timesteps", "768", "--seed", "1"]))
    with pytest.raises(ValueError, match=r"holds a run of 512 env steps; --timesteps 256 cannot shrink it"):
        main(parse_args([*args, "--timesteps", "256"]))
    assert json.loads((tmp_path / "run" / "training.json").read_text())["config"]["timesteps"] == 512


@pytest.mark.parametrize("damage", ["missing", "garbage", "list"])
def test_a_saved_run_without_readable_settings_is_one_error_line(tmp_path: Path, damage: str,
                                                                 capsys: pytest.CaptureFixture) -> None:
    from st_sim.apps.navigation.train_ppo import cli

    run = tmp_path / "run"
    run.mkdir()
    (run / "resume.zip").write_bytes(b"PK")
    if damage != "missing":
        (run / "resume.json").write_text("{not json" if damage == "garbage" else "[1, 2]")
    assert cli(["--no-predictions", "--num-envs", "2", "--timesteps", "256", "--out", str(run), "--quiet"]) == 1
    err = capsys.readouterr().err
    assert err.startswith(f"error: {run}/resume") and err.count("\n") == 1, err


def test_dropping_the_prediction_columns_gives_the_features_without_predictions() -> None:
    """Collection encodes once and derives the other variant: it must equal encoding without predictions."""
    import gymnasium as gym

    import envs  # noqa: F401  (registers the ids)
    from st_sim.apps.navigation.features import drop_predictions, encode
    from st_sim.apps.navigation.world import world_of

    env = gym.make("STCrowd-SimCrossing-v1", predictor="cvm-s")
    world = world_of(env)
    obs, _ = env.reset(seed=3)
    for _ in range(4):
        with_predictions = encode(obs, world, FeatureConfig(True))
        np.testing.assert_array_equal(drop_predictions(with_predictions), encode(obs, world, FeatureConfig(False)))
        obs, *_ = env.step(np.array([1.0, 0.0], np.float32))
    env.close()


def test_ppo_starts_from_a_policy_file_and_fits_its_critic_first(tmp_path: Path) -> None:
    """``--init-policy``: PPO of another seed starts from a saved clone's weights; ``--critic-rollouts``: its first
    updates change the critic only (the actor's mean action is the clone's), later ones the actor too; a policy
    that reads other features is refused."""
    import torch

    from st_sim.apps.navigation.ppo import load_policy
    from st_sim.apps.navigation.train_ppo import main, parse_args

    common = ["--no-predictions", "--num-envs", "2", "--shards", "1", "--n-steps", "16", "--batch-size", "16",
              "--quiet"]
    clone = main(parse_args([*common, "--timesteps", "0", "--seed", "3", "--out", str(tmp_path / "clone")]))
    start, _ = load_policy(clone)
    probe = torch.as_tensor(np.random.default_rng(0).normal(size=(32, start.observation_space.shape[0])),
                            dtype=torch.float32)

    def mean_action(path: Path) -> torch.Tensor:
        policy, _ = load_policy(path)
        with torch.no_grad():
            return policy.get_distribution(probe).distribution.mean

    def value(path: Path) -> torch.Tensor:
        policy, _ = load_policy(path)
        with torch.no_grad():
            return policy.predict_values(probe)

    held = main(parse_args([*common, "--timesteps", "32", "--init-policy", str(clone), "--critic-rollouts", "5",
                            "--out", str(tmp_path / "held")]))
    torch.testing.assert_close(mean_action(held), mean_action(clone), rtol=0, atol=0)
    assert not torch.allclose(value(held), value(clone))
    moved = main(parse_args([*common, "--timesteps", "64", "--init-policy", str(clone), "--critic-rollouts", "1",
                             "--out", str(tmp_path / "moved")]))
    assert not torch.allclose(mean_action(moved), mean_action(clone))
    with pytest.raises(ValueError, match="reads"):
        main(parse_args(["--num-envs", "2", "--shards", "1", "--timesteps", "16", "--n-steps", "8", "--quiet",
                         "--init-policy", str(clone), "--out", str(tmp_path / "other")]))


def test_a_run_records_the_init_policy_it_started_from_even_after_that_file_is_replaced(tmp_path: Path) -> None:
    """``training.json`` keeps the SHA-256 of the ``--init-policy`` file as it was when the run started; a later
    segment, resumed after another policy took the file's path (as shipping a policy over its own start does),
    still names the first file."""
    import hashlib
    import shutil

    from st_sim.apps.navigation.train_ppo import main, parse_args

    common = ["--no-predictions", "--num-envs", "2", "--shards", "1", "--n-steps", "16", "--batch-size", "16",
              "--quiet"]
    first = main(parse_args([*common, "--timesteps", "0", "--seed", "3", "--out", str(tmp_path / "a")]))
    other = main(parse_args([*common, "--timesteps", "0", "--seed", "4", "--out", str(tmp_path / "b")]))
    start = tmp_path / "start.pt"
    shutil.copyfile(first, start)
    started = hashlib.sha256(start.read_bytes()).hexdigest()
    run = [*common, "--init-policy", str(start), "--out", str(tmp_path / "run")]
    main(parse_args([*run, "--timesteps", "32"]))
    assert json.loads((tmp_path / "run" / "training.json").read_text())["init_policy_sha256"] == started
    shutil.copyfile(other, start)
    assert hashlib.sha256(start.read_bytes()).hexdigest() != started
    main(parse_args([*run, "--timesteps", "64"]))
    record = json.loads((tmp_path / "run" / "training.json").read_text())
    assert record["resumed_from"] == 32 and record["init_policy_sha256"] == started
    scratch = main(parse_args([*common, "--timesteps", "16", "--out", str(tmp_path / "scratch")]))
    assert json.loads((scratch.parent / "training.json").read_text())["init_policy_sha256"] is None
