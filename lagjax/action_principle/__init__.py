"""The action S = ∫L dt: of a path, along a trajectory, and between end points."""

from lagjax.action_principle.hamilton_principle import action as action
from lagjax.action_principle.hamilton_principle import action_of_path as action_of_path
from lagjax.action_principle.hamilton_principle import (
    principal_function as principal_function,
)
from lagjax.action_principle.shooting import action_between as action_between
from lagjax.action_principle.shooting import trajectory_between as trajectory_between
