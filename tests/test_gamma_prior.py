"""GAMMA priors: canonical windows, the marker CVAE, the body regressor and the pose VAE."""

from __future__ import annotations

import dataclasses

import pytest
import torch

from motion_envs.data.primitives import PRIMITIVE_FRAMES
from motion_envs.precision import native_bf16
from motion_envs.body.canonical_frame import canonical_frame, to_canonical, to_world
from motion_envs.priors.gamma import (
    BodyRegressor,
    MarkerCVAE,
    MarkerCVAEConfig,
    PoseVAE,
    pose_vae_loss,
    predictor_loss,
    robust_kl,
    to_axis_angle,
)
from motion_envs.body.markers import marker_ids
from motion_envs.priors.train_regressor import regressor_loss


def test_canonical_frame_round_trip_and_axes(generator):
    joints = torch.randn(5, 22, 3, generator=generator)
    frame = canonical_frame(joints)
    points = torch.randn(5, 7, 3, generator=generator)
    assert torch.allclose(to_world(to_canonical(points, frame), frame), points, atol=1e-5)
    # the turn about z written out per axis is the frame's rotation matrix
    assert torch.allclose(to_world(points, frame), points @ frame.rotation.mT + frame.origin[:, None], atol=1e-5)
    canonical = to_canonical(joints, frame)
    assert torch.allclose(canonical[:, 0], torch.zeros(5, 3), atol=1e-5)  # pelvis at the origin
    across = canonical[:, 2] - canonical[:, 1]  # right hip - left hip lies along +x
    assert torch.allclose(across[:, 1], torch.zeros(5), atol=1e-5) and (across[:, 0] > 0).all()


def test_windows_are_canonical_at_their_first_frame(walking_clips, body):
    starts = walking_clips.window_starts(PRIMITIVE_FRAMES, stride=5)
    windows = walking_clips.windows(starts, PRIMITIVE_FRAMES)
    assert windows.markers.shape == (len(starts), PRIMITIVE_FRAMES, 67, 3)
    assert windows.joints[:, 0, 0].abs().max() < 1e-5
    posed = body(windows.transl, windows.global_orient, windows.body_pose)
    assert (body.skin(posed, marker_ids()) - windows.markers).abs().max() < 1e-4
    walked = windows.joints[:, -1, 0, 1]  # pelvis forward travel over 0.25 s of walking
    assert walked.median() > 0.15


def test_marker_cvae_overfits_a_few_primitives(walking_clips):
    torch.manual_seed(0)
    starts = walking_clips.window_starts(PRIMITIVE_FRAMES, stride=5)[:16]
    markers = walking_clips.windows(starts, PRIMITIVE_FRAMES).markers.flatten(2)
    model = MarkerCVAE(MarkerCVAEConfig(seed_frames=2, hidden=64, latent=16, mlp=(64, 64)))
    optimiser = torch.optim.Adam(model.parameters(), lr=3e-3)
    seed, future = markers[:, :2], markers[:, 2:]
    losses = []
    for _ in range(60):
        optimiser.zero_grad()
        terms = predictor_loss(seed, future, *model(seed, future))
        terms["total"].backward()
        optimiser.step()
        losses.append(terms["reconstruction"].item())
    assert losses[-1] < 0.5 * losses[0]
    assert model.decode(seed, torch.zeros(16, 16)).shape == (16, 8, 201)


def test_marker_cvae_rejects_wrong_shapes():
    model = MarkerCVAE(MarkerCVAEConfig(seed_frames=1))
    with pytest.raises(ValueError, match=r"seed must be \(B, 1, 201\)"):
        model.decode(torch.zeros(2, 2, 201), torch.zeros(2, 128))
    with pytest.raises(ValueError, match="seed_frames"):
        MarkerCVAE(MarkerCVAEConfig(seed_frames=3))


def test_robust_kl_is_zero_at_zero_and_grows_linearly():
    values = robust_kl(torch.tensor([0.0, 1.0, 100.0]))
    assert values[0] == 0 and abs(values[1] - (2**0.5 - 1)) < 1e-6 and abs(values[2] - 99.005) < 1e-2


def test_body_regressor_learns_markers_to_bodies(walking_clips, body):
    torch.manual_seed(0)
    starts = walking_clips.window_starts(PRIMITIVE_FRAMES, stride=5)[:16]
    windows = walking_clips.windows(starts, PRIMITIVE_FRAMES)
    markers = windows.markers.flatten(0, 1)
    model = BodyRegressor()
    optimiser = torch.optim.Adam(model.parameters(), lr=1e-3)
    errors = []
    for _ in range(80):
        optimiser.zero_grad()
        terms = regressor_loss(model, body, markers, pose_weight=1e-3)
        terms["total"].backward()
        optimiser.step()
        errors.append(terms["marker_error"].item())
    assert errors[-1] < 0.5 * errors[0]
    assert to_axis_angle(model(markers[:2]))["body_pose"].shape == (2, 21, 3)


def test_pose_vae_loss_falls(walking_clips):
    torch.manual_seed(0)
    model = PoseVAE()
    optimiser = torch.optim.Adam(model.parameters(), lr=1e-3)
    poses = walking_clips.body_pose[::4]
    first = pose_vae_loss(model, poses)["reconstruction"].item()
    for _ in range(100):
        optimiser.zero_grad()
        pose_vae_loss(model, poses)["total"].backward()
        optimiser.step()
    assert pose_vae_loss(model, poses)["reconstruction"].item() < 0.5 * first


def test_predictor_training_resumes_and_writes_loadable_weights(walking_clips, tmp_path, capsys):
    from motion_envs.priors.checkpoint import CheckpointMismatchError, load_checkpoint
    from motion_envs.priors.train_gamma import PredictorTrainConfig, load_predictor, train_predictor

    small = MarkerCVAEConfig(seed_frames=2, hidden=32, latent=8, mlp=(32, 32))
    config = PredictorTrainConfig(model=small, epochs=3, rollout_epochs=0, rollout_primitives=2, batch_size=8,
                                  window_stride=1, run_dir=tmp_path / "run", weights=tmp_path / "w" / "p.pt")  # fmt: skip
    first = train_predictor(config, walking_clips, walking_clips)
    assert first["train_loss_by_epoch"][-1] < first["train_loss_by_epoch"][0]
    config.rollout_epochs = 1  # one more epoch, now chaining 2 primitives: resumes at epoch 3
    second = train_predictor(config, walking_clips, walking_clips)
    assert "resuming" in capsys.readouterr().err
    assert second["train_loss_by_epoch"][:3] == first["train_loss_by_epoch"] and len(second["train_loss_by_epoch"]) == 4
    errors = second["validation_marker_error_cm_per_frame"]
    assert len(errors["primitive"]) == 8 and len(errors["rollout_2"]) == 16
    model = load_predictor(config.weights)
    assert model.decode(torch.zeros(1, 2, 201), torch.zeros(1, 8)).shape == (1, 8, 201)
    assert (config.weights.parent / "manifest.json").exists()
    with pytest.raises(CheckpointMismatchError, match="expected 'gamma_regressor'"):
        load_checkpoint(config.weights, "gamma_regressor")
    with pytest.raises(CheckpointMismatchError, match="config"):
        load_checkpoint(config.run_dir / "checkpoint.pt", "gamma_predictor_run", {"seed_frames": 1})


def test_regressor_and_pose_vae_training_runs_write_loadable_weights(walking_clips, tmp_path, capsys):
    from motion_envs.priors.gamma import BodyRegressorConfig, PoseVAEConfig
    from motion_envs.priors.train_pose_prior import PoseVAETrainConfig, load_pose_vae, train_pose_vae, validate_pose_vae
    from motion_envs.priors.train_regressor import RegressorTrainConfig, load_regressor, train_regressor

    config = RegressorTrainConfig(model=BodyRegressorConfig(hidden=32, blocks=2), epochs=3, batch_size=4,
                                  learning_rate=1e-3, window_stride=10, run_dir=tmp_path / "r", weights=tmp_path / "w" / "r.pt")  # fmt: skip
    entry = train_regressor(config, walking_clips, walking_clips)
    assert entry["train_loss_by_epoch"][-1] < entry["train_loss_by_epoch"][0]
    assert entry["validation"]["marker_error_cm"] > 0
    config.epochs = 4  # resumes at epoch 3
    assert len(train_regressor(config, walking_clips, walking_clips)["train_loss_by_epoch"]) == 4
    assert "resuming" in capsys.readouterr().err
    assert load_regressor(config.weights)(torch.zeros(2, 67, 3))["body_pose"].shape == (2, 21, 6)

    poses = walking_clips.body_pose
    vae = PoseVAETrainConfig(model=PoseVAEConfig(hidden=32, latent=4), epochs=3, batch_size=64, run_dir=tmp_path / "v",
                             weights=tmp_path / "w" / "v.pt")  # fmt: skip
    torch.manual_seed(vae.seed)
    untrained = validate_pose_vae(PoseVAE(vae.model), poses)["joint_angle_error_deg"]
    entry = train_pose_vae(vae, poses, poses)
    assert entry["train_loss_by_epoch"][-1] < entry["train_loss_by_epoch"][0]
    assert 0 < entry["validation"]["joint_angle_error_deg"] < untrained
    assert load_pose_vae(vae.weights).encode(poses[:3])[0].shape == (3, 4)
    manifest = (tmp_path / "w" / "manifest.json").read_text()
    assert '"r.pt"' in manifest and '"v.pt"' in manifest


def test_training_writes_to_its_run_folder_unless_shipped(walking_clips, tmp_path, monkeypatch, capsys):
    """A run without `weights` once replaced the shipped pose VAE; now only `ship=True` writes into the package
    (here a copy of the weights folder: WEIGHTS_DIR points at it) and says what it replaces."""
    import shutil

    from motion_envs.priors import training
    from motion_envs.priors.gamma import PoseVAEConfig
    from motion_envs.priors.train_pose_prior import PoseVAETrainConfig, train_pose_vae

    shipped = training.WEIGHTS_DIR / "gamma_pose_vae.pt"
    before = shipped.read_bytes()
    poses = walking_clips.body_pose
    config = PoseVAETrainConfig(model=PoseVAEConfig(hidden=16, latent=4), epochs=1, batch_size=64, run_dir=tmp_path / "run")
    train_pose_vae(config, poses, poses)
    assert (tmp_path / "run" / "gamma_pose_vae.pt").is_file() and shipped.read_bytes() == before
    package = tmp_path / "package_weights"
    package.mkdir()
    for name in ("gamma_pose_vae.pt", "manifest.json"):
        shutil.copy(training.WEIGHTS_DIR / name, package / name)
    monkeypatch.setattr(training, "WEIGHTS_DIR", package)
    capsys.readouterr()
    train_pose_vae(dataclasses.replace(config, ship=True, run_dir=tmp_path / "run2"), poses, poses)
    assert (package / "gamma_pose_vae.pt").read_bytes() != before and shipped.read_bytes() == before
    assert "replacing the shipped" in capsys.readouterr().err


@pytest.mark.parametrize("dtype", [torch.float32, torch.bfloat16])
def test_onednn_linears_match_the_plain_modules(generator, dtype):
    """The no-grad CPU path (oneDNN: matmul, bias and activation in one call) computes what the modules compute
    with autograd on (MKL's matmul, then the activation): fp32 to reassociation (1e-5 here), bf16 to its 3 digits.
    Covers every layer kind the priors use: residual blocks, the tanh MLP, leaky-ReLU layers, a strided weight, a sum
    fused into the linear (`add`), and the regressor and the predictor's decoder, which fuse their sums that way."""
    from motion_envs.priors.gamma import BodyRegressor, MarkerCVAE, MarkerCVAEConfig, PoseVAE, ResidualBlock, tanh_mlp
    from motion_envs.priors.inference_linear import ONEDNN_LINEAR, linear, takes_onednn

    x = torch.randn(64, 8, 128, generator=generator).to(dtype)
    if ONEDNN_LINEAR is None or (dtype == torch.bfloat16 and not native_bf16()):
        pytest.skip("no oneDNN linear, or bf16 without native bf16 here: the plain path is the only one")
    tolerance = {"atol": 1e-5, "rtol": 1e-5} if dtype == torch.float32 else {"atol": 2e-2, "rtol": 2e-2}
    pose_vae = PoseVAE().to(dtype)
    weight = torch.randn(96, 300, generator=generator).to(dtype)
    bias, summand = torch.randn(96, generator=generator).to(dtype), torch.randn(64, 96, generator=generator).to(dtype)
    regressor, predictor = BodyRegressor().to(dtype), MarkerCVAE(MarkerCVAEConfig()).to(dtype)
    latent = torch.randn(64, predictor.config.latent, generator=generator).to(dtype)
    cases = [
        (ResidualBlock(128).to(dtype), x),
        (tanh_mlp([128, 512, 256]).to(dtype), x),
        (lambda poses: pose_vae.encode(poses)[0], torch.randn(64, 21, 6, generator=generator).to(dtype)),
        (lambda rows: linear(rows, weight[:, 100:]), torch.randn(64, 200, generator=generator).to(dtype)),
        (lambda rows: linear(rows, weight[:, :200], bias, add=summand), torch.randn(64, 200, generator=generator).to(dtype)),
        (lambda markers: regressor(markers)["body_pose"], torch.randn(64, 67, 3, generator=generator).to(dtype)),
        (lambda seed: predictor.decode(seed, latent), torch.randn(64, 2, 201, generator=generator).to(dtype)),
    ]
    for module, inputs in cases:
        with torch.enable_grad():
            plain = module(inputs)
        with torch.no_grad():
            assert takes_onednn(inputs)
            fused = module(inputs)
        assert fused.dtype == dtype and torch.allclose(fused.float(), plain.float(), **tolerance)
