"""Rollout files, the mannequin-x pose mapping, and the browser viewer opened for real in headless Chromium."""

from __future__ import annotations

import os
import shutil
import socket
import threading

import imageio.v3 as iio
import numpy as np
import pytest
import torch

from motion_envs.rollout import Rollout, RolloutRecorder


def test_rollout_files_round_trip_and_bad_files_fail_clearly(tmp_path):
    recorder = RolloutRecorder(30.0, "sphere", 0.1, env_id="motion_envs/WandrReach-v0")
    rotations = torch.randn(4, 22, 3) * 0.3
    for frame in range(4):
        recorder.add(torch.full((2, 3), float(frame)), rotations[frame : frame + 1, 0].expand(2, 3),
                     rotations[frame : frame + 1, 1:].expand(2, 21, 3), torch.ones(2, 3))  # fmt: skip
    rollout = recorder.rollout()
    assert (rollout.frames, rollout.bodies) == (4, 2) and len(recorder) == 4
    loaded = Rollout.load(rollout.save(tmp_path / "r.npz"))
    np.testing.assert_allclose(loaded.rotations[:, 1], rotations.numpy(), atol=1e-5)
    assert (loaded.fps, loaded.goal_shape, loaded.goal_radius, loaded.env_id) == (30.0, "sphere", 0.1, "motion_envs/WandrReach-v0")
    np.savez(tmp_path / "other.npz", transl=np.zeros((2, 1, 3)))
    with pytest.raises(ValueError, match="missing"):
        Rollout.load(tmp_path / "other.npz")
    (tmp_path / "junk.npz").write_bytes(b"not a zip")
    with pytest.raises(ValueError, match="junk.npz"):
        Rollout.load(tmp_path / "junk.npz")
    with pytest.raises(ValueError, match="rotations"):
        Rollout(np.zeros((3, 1, 3)), np.zeros((3, 1, 21, 3)), np.zeros((3, 1, 3)), fps=30.0)


def test_mannequin_pose_puts_every_joint_where_our_body_does(body):
    import mannequin

    from motion_envs.viewer import mannequin_pose

    model = mannequin.Mannequin("wooden")
    template = model.rest_pose()
    offset = np.asarray(model.joint_transforms(mannequin_pose(template, np.zeros(3), np.zeros((22, 3)), np.zeros(3))))[0, :3, 3]
    generator = torch.Generator().manual_seed(0)
    transl, rotations = torch.randn(3, generator=generator), torch.randn(22, 3, generator=generator) * 0.5
    ours = body(transl[None], rotations[None, 0], rotations[None, 1:]).joints[0].numpy()
    theirs = np.asarray(model.joint_transforms(mannequin_pose(template, transl.numpy(), rotations.numpy(), offset)))[:22, :3, 3]
    np.testing.assert_allclose(theirs, ours, atol=1e-5)


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def _chromium() -> str:
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    if chromium is None:
        message = "headless Chromium not found (Debian package `chromium`; .ci/run installs it)"
        if os.environ.get("CI", "").lower() == "true":
            pytest.fail(message)
        pytest.skip(message)
    return chromium


def _wood_pixels_on_screen(viewer, path) -> int:
    """Play `viewer` while headless Chromium opens its page; the screenshot's count of mannequin-wood pixels."""
    from playwright.sync_api import sync_playwright

    chromium = _chromium()
    port = viewer.server.get_port()
    player = threading.Thread(target=viewer.run, kwargs={"duration": 30.0}, daemon=True)
    player.start()
    try:
        with sync_playwright() as playwright:
            browser = playwright.chromium.launch(executable_path=chromium, args=["--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--no-sandbox"])
            page = browser.new_page(viewport={"width": 640, "height": 480})
            page.goto(f"http://127.0.0.1:{port}")
            page.wait_for_selector("canvas", timeout=60_000)
            frames_seen = set()
            for _ in range(50):  # 5 s; the timeline may wrap back to frame 0 at any moment, so watch it move
                page.wait_for_timeout(100)
                frames_seen.add(int(viewer.slider.value))
            page.screenshot(path=str(path))
            browser.close()
        assert len(frames_seen) > 1, frames_seen  # the timeline played
    finally:
        viewer.stop()
        player.join(timeout=5)
    pixels = iio.imread(path)[140:420, :, :3].reshape(-1, 3).astype(int)  # between viser's panels (its banner is orange) and axes
    assert pixels.std(axis=0).mean() > 5  # not a blank canvas
    wood = (pixels[:, 0] > pixels[:, 2] + 60) & (pixels[:, 0] > pixels[:, 1] + 20)  # mannequin-x's wood palette
    return int(wood.sum())


def test_browser_viewer_replays_a_rollout_with_the_body_on_the_canvas(tmp_path):
    _chromium()
    from motion_envs.play import play
    from motion_envs.viewer import RolloutViewer

    path = tmp_path / "episode.npz"
    play("motion_envs/WandrReach-v0", seed=3, save_rollout=path, max_frames=45)
    viewer = RolloutViewer(Rollout.load(path), port=_free_port())
    assert _wood_pixels_on_screen(viewer, tmp_path / "viewer.png") > 200


def test_browser_viewer_opens_on_a_body_in_its_room_over_cut_walls(tmp_path):
    """A body near the room's corner towards the old opening camera (3.5 m out along -x, -y) was hidden behind
    2.5 m walls. An `open` room has no wood-coloured furniture, so wood on screen is the body."""
    _chromium()
    from motion_envs.envs.gamma_wander import GammaWanderEnv
    from motion_envs.viewer import RolloutViewer

    env = GammaWanderEnv(scene="open", scene_seeds=(1000,))
    env.reset(seed=0, options={"start": [0.8, 0.8], "goal": [3.0, 3.0]})
    recorder = RolloutRecorder(2.0, *env.core.goal_marker, env_id="motion_envs/GammaWander-v0", scene="open:1000")
    for _ in range(60):  # 30 s at 2 frames/s: the timeline does not wrap back to 0 before the screenshot
        inputs = env.core.render_inputs(env.state)
        recorder.add(inputs.transl, inputs.global_orient, inputs.body_pose, inputs.goal)
        env.step(np.zeros(128, dtype=np.float32))
    viewer = RolloutViewer(recorder.rollout(), env.core.scenes[0], port=_free_port())
    assert _wood_pixels_on_screen(viewer, tmp_path / "room.png") > 200


def test_a_viewer_on_a_busy_port_reports_the_port_it_bound(tmp_path):
    """viser moves to the next free port when the asked one is taken; `view` printed the asked one (the URL of
    whatever server held it)."""
    from motion_envs.viewer import RolloutViewer

    recorder = RolloutRecorder(30.0, "sphere", 0.1)
    recorder.add(torch.zeros(1, 3), torch.zeros(1, 3), torch.zeros(1, 21, 3), torch.ones(1, 3))
    busy = socket.socket()
    busy.bind(("127.0.0.1", 0))
    busy.listen()
    taken = busy.getsockname()[1]
    try:
        viewer = RolloutViewer(recorder.rollout(), port=taken)
        try:
            assert viewer.url.startswith("http://127.0.0.1:") and viewer.url != f"http://127.0.0.1:{taken}"
            assert int(viewer.url.rsplit(":", 1)[1]) == viewer.server.get_port()
        finally:
            viewer.stop()
    finally:
        busy.close()


def test_view_help_lists_every_env():
    import subprocess
    import sys

    text = subprocess.run([sys.executable, "-m", "motion_envs.cli", "view", "--help"], capture_output=True, text=True,
                          timeout=60, check=True).stdout  # fmt: skip
    assert all(name in " ".join(text.split()) for name in ("GammaReach-v0", "WandrReach-v0", "ClopsNav-v0", "--env-option"))
