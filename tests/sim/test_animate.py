"""`relaff show --rollout`: the ray-cast frames draw shapes as they are (a ball is a disc), the
title marks an infeasible program, and one sample's program replayed in MuJoCo C and written
as a GIF."""
import copy

import mujoco
import numpy as np
import pytest

from relaff_jax.sim import animate


def _ball_scene():
    from relaff_jax.sim.planning import setup
    from relaff_jax.sim.templates import ActionConfig

    w = setup(ActionConfig()).world
    m = copy.copy(w.mj_models[w.pair_index[("ball", "tray")]])
    m.geom_rgba[:, :3] = 0.6  # everything grey, the ball pure green
    ball = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "toy_sphere")
    m.geom_rgba[ball] = (0.0, 1.0, 0.0, 1.0)
    d = mujoco.MjData(m)
    d.qpos[:7] = (0.8, 0.15, 0.2, 1, 0, 0, 0)  # the ball in the air beside the tray
    d.qpos[7:14] = (0.8, -0.15, 0.0, 1, 0, 0, 0)
    mujoco.mj_forward(m, d)
    frames = {"model": m, "frames_xpos": d.geom_xpos.copy()[None], "frames_xmat": d.geom_xmat.copy()[None],
              "object_bodies": (w.toy_body, w.obj_body), "every": 10, "label": False}
    return frames, m.geom_size[ball, 0]


def test_a_ray_cast_ball_is_a_disc():
    """The ball's pixels fill pi/4 of their bounding box (a disc; its bounding box drawn would
    fill all of it), its corners empty."""
    from relaff_jax.perception import rollout_view as rv

    frames, _ = _ball_scene()
    cam = rv.frame_camera(frames["model"], frames["frames_xpos"], frames["object_bodies"], width=800, height=600)
    img = rv.shade_frames(frames["model"], frames["frames_xpos"], frames["frames_xmat"], cam)[0].astype(int)
    mask = (img[..., 1] > img[..., 0] + 30) & (img[..., 1] > img[..., 2] + 30)
    rows, cols = np.flatnonzero(mask.any(1)), np.flatnonzero(mask.any(0))
    h, w = rows[-1] - rows[0] + 1, cols[-1] - cols[0] + 1
    assert h > 20 and abs(h - w) <= 2  # round, not squashed, and large enough to judge
    assert mask.sum() / (h * w) == pytest.approx(np.pi / 4, abs=0.03)
    box = mask[rows[0]:rows[-1] + 1, cols[0]:cols[-1] + 1]
    assert not box[0, 0] and not box[-1, -1] and not box[0, -1] and not box[-1, 0]  # corners empty


def test_gif_marks_an_infeasible_program(tmp_path):
    from PIL import Image

    frames, _ = _ball_scene()
    shown = []
    for feasible in (True, False):
        f = dict(frames, feasible=feasible)
        animate.write_gif(f, tmp_path / f"{feasible}.gif", title="lift sample 0: ball + tray")
        im = np.asarray(Image.open(tmp_path / f"{feasible}.gif").convert("RGB")).astype(int)
        red = (im[..., 0] > 150) & (im[..., 1] < 80) & (im[..., 2] < 80)
        shown.append(red[:60].sum())
        assert f["seconds_per_frame"] > 0
    assert shown[0] == 0 and shown[1] > 50  # only the infeasible title has the red line
@pytest.mark.slow  # plans (IK compile) and replays 560 C steps
def test_rollout_gif_of_a_settled_scene(tmp_path, scene_world, settle):
    import jax
    from PIL import Image

    from relaff_jax.sim import scenes
    from relaff_jax.sim.rollouts import allowed_pairs

    place, _, _ = scenes.jitted_scene_fns(scene_world)
    # 8 scenes (the first is animated): the batch of the session's settle program, which the
    # other files' tests compile or load, rather than a settle compiled for this test alone
    pair = np.asarray(allowed_pairs(scene_world, "lift")[:8], np.int32)
    assert pair.shape == (8,)
    qpos0, intended = place(jax.random.PRNGKey(3), pair)
    s = settle(pair, qpos0, intended)
    heard = []
    frames = animate.animate_sample("lift", int(pair[0]), np.asarray(s.qpos)[0], tmp_path / "a.gif", title="t",
                                    every=40, progress=lambda *a: heard.append(a))
    from relaff_jax.constants import action_id
    from relaff_jax.sim import templates
    from relaff_jax.sim.actions.tables import DESCENT_DWELL, run_steps

    # a frame every 40 steps of the program (the CLI's default is 10; fewer frames keep the
    # test short), which stops at its end (560 of lift's template steps, v4's dwell before the
    # descent, and the 200 more to read the goal at rest)
    n_run = int(run_steps(templates.ActionConfig())[action_id("lift")])
    assert n_run == 560 + DESCENT_DWELL + templates.ActionConfig().rest_hold
    assert frames["frames_xpos"].shape[0] == 1 + n_run // 40
    # every phase is announced and finished; the frames are counted one by one
    phases = list(dict.fromkeys(h[0] for h in heard))
    assert phases == ["planning (compiles the IK first)", "replaying in MuJoCo C", "drawing frames"]
    drawn = [h[1] for h in heard if h[0] == "drawing frames"]
    assert drawn == list(range(1 + n_run // 40 + 1))
    im = Image.open(tmp_path / "a.gif")
    assert im.n_frames == frames["frames_xpos"].shape[0]
    # the objects start where the scene settled
    model = frames["model"]
    toy_geom = np.flatnonzero(np.asarray(model.geom_bodyid) == scene_world.toy_body)[0]
    assert np.linalg.norm(frames["frames_xpos"][0, toy_geom, :2] - np.asarray(s.qpos)[0, :2]) < 0.2
