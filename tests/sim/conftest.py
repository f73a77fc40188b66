"""Fixtures of the simulation tests: the arm's own MuJoCo model (no objects) and its tables."""
import mujoco
import pytest

from relaff_jax.sim import arm as A


@pytest.fixture(scope="module")
def model():
    """The arm's test model (``arm.arm_test_xml_path``): MuJoCo C's reference kinematics."""
    return mujoco.MjModel.from_xml_path(str(A.arm_test_xml_path()))


@pytest.fixture(scope="module")
def arm(model):
    """The ``Arm`` tables of that model."""
    return A.arm_from_model(model)
