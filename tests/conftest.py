"""Shared fixtures: the world and its jitted settle function are built once per session
(compiling an MJX step costs tens of seconds on two cores)."""
import pytest

from relaff_jax import scenes, world


@pytest.fixture(scope="session")
def scene_world():
    return world.build_world()


@pytest.fixture(scope="session")
def settle(scene_world):
    """jitted ``settle_fn(pair, qpos0, intended)`` of the default config."""
    return scenes.jitted_scene_fns(scene_world)[1]
