"""`relaff show --rollout`: the outline projection on hand-worked boxes, and one sample's
program replayed in MuJoCo C and written as a GIF."""
import numpy as np
import pytest

from relaff_jax.sim import animate


def test_box_outline_side_and_top_views():
    aabb = np.array([[0.0, 0.0, 0.0, 0.1, 0.2, 0.3]])  # centre, half sizes
    xpos = np.array([[1.0, 2.0, 3.0]])
    eye = np.eye(3).reshape(1, 9)
    (poly, depth), = animate.geom_outlines(aabb, xpos, eye, animate.VIEWS["side (x-z)"])
    assert depth == 2.0
    assert len(poly) == 4
    np.testing.assert_allclose(poly.min(0), [0.9, 2.7])
    np.testing.assert_allclose(poly.max(0), [1.1, 3.3])
    # turned 90 degrees about z: the side view sees the 0.2 half size along x
    rz = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]).reshape(1, 9)
    (poly, _), = animate.geom_outlines(aabb, xpos, rz, animate.VIEWS["side (x-z)"])
    np.testing.assert_allclose(poly.min(0), [0.8, 2.7], atol=1e-12)
    # an offset box centre (a geom off its body's origin) moves the outline with the rotation
    off = np.array([[0.5, 0.0, 0.0, 0.1, 0.1, 0.1]])
    (poly, _), = animate.geom_outlines(off, xpos, rz, animate.VIEWS["top (x-y)"])
    np.testing.assert_allclose(poly.mean(0), [1.0, 2.5], atol=1e-12)


@pytest.mark.slow  # plans (IK compile) and replays 560 C steps
def test_rollout_gif_of_a_settled_scene(tmp_path, scene_world, settle):
    import jax
    from PIL import Image

    from relaff_jax.sim import scenes
    from relaff_jax.sim.rollouts import allowed_pairs

    place, _, _ = scenes.jitted_scene_fns(scene_world)
    pair = np.asarray(allowed_pairs(scene_world, "lift")[:2], np.int32)
    qpos0, intended = place(jax.random.PRNGKey(3), pair)
    s = settle(pair, qpos0, intended)
    heard = []
    frames = animate.animate_sample("lift", int(pair[0]), np.asarray(s.qpos)[0], tmp_path / "a.gif", title="t",
                                    every=40, progress=lambda *a: heard.append(a))
    from relaff_jax.constants import action_id
    from relaff_jax.sim import templates

    # a frame every 40 steps of the program (the CLI's default is 10; fewer frames keep the
    # test short), which stops at its end (560 of lift's 815 steps)
    n_run = int(templates.run_steps(templates.ActionConfig())[action_id("lift")])
    assert n_run == 560
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
