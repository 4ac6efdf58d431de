"""Rigid bodies: inertia, orientation (Euler angles, quaternions) and dynamics.

- `inertia`, `solids`: inertia tensors, the axis theorems, principal axes.
- `euler_angles`, `quaternion`: orientations and angular velocities.
- `body`: `RigidBody` (Euler's equations on quaternions; its diffrax term is `lagjax._core.terms.RigidBodyTerm`);
  the structure-preserving solvers are in `lagjax.solvers.lie_poisson`.
- `free_body`, `heavy_top`: closed forms (precession, periods, nutation bounds).
"""

from lagjax.rigid.body import RigidBody as RigidBody
from lagjax.rigid.euler_angles import (
    euler_zxz_body_angular_velocity as euler_zxz_body_angular_velocity,
)
from lagjax.rigid.euler_angles import euler_zxz_matrix as euler_zxz_matrix
from lagjax.rigid.euler_angles import (
    euler_zxz_space_angular_velocity as euler_zxz_space_angular_velocity,
)
from lagjax.rigid.euler_angles import euler_zxz_to_quaternion as euler_zxz_to_quaternion
from lagjax.rigid.euler_angles import euler_zxz_to_rotation as euler_zxz_to_rotation
from lagjax.rigid.euler_angles import rotation_to_euler_zxz as rotation_to_euler_zxz
from lagjax.rigid.free_body import free_body_period as free_body_period
from lagjax.rigid.free_body import (
    invariable_plane_distance as invariable_plane_distance,
)
from lagjax.rigid.free_body import space_precession_rate as space_precession_rate
from lagjax.rigid.free_body import (
    symmetric_precession_rate as symmetric_precession_rate,
)
from lagjax.rigid.heavy_top import (
    gyroscopic_precession_rates as gyroscopic_precession_rates,
)
from lagjax.rigid.heavy_top import nutation_bounds as nutation_bounds
from lagjax.rigid.heavy_top import steady_precession_rates as steady_precession_rates
from lagjax.rigid.heavy_top import turning_point_cubic as turning_point_cubic
from lagjax.rigid.inertia import TopKind as TopKind
from lagjax.rigid.inertia import centre_of_mass as centre_of_mass
from lagjax.rigid.inertia import parallel_axis as parallel_axis
from lagjax.rigid.inertia import perpendicular_axis as perpendicular_axis
from lagjax.rigid.inertia import point_mass_inertia as point_mass_inertia
from lagjax.rigid.inertia import principal_axes as principal_axes
from lagjax.rigid.inertia import top_kind as top_kind
from lagjax.rigid.quaternion import axis_angle_quaternion as axis_angle_quaternion
from lagjax.rigid.quaternion import body_angular_velocity as body_angular_velocity
from lagjax.rigid.quaternion import matrix_to_quaternion as matrix_to_quaternion
from lagjax.rigid.quaternion import quaternion_conjugate as quaternion_conjugate
from lagjax.rigid.quaternion import quaternion_multiply as quaternion_multiply
from lagjax.rigid.quaternion import quaternion_rate as quaternion_rate
from lagjax.rigid.quaternion import quaternion_to_matrix as quaternion_to_matrix
from lagjax.rigid.quaternion import rotate as rotate
from lagjax.rigid.quaternion import (
    rotation_vector_quaternion as rotation_vector_quaternion,
)
from lagjax.rigid.quaternion import skew as skew
from lagjax.rigid.quaternion import space_angular_velocity as space_angular_velocity
from lagjax.rigid.solids import box_inertia as box_inertia
from lagjax.rigid.solids import cone_apex_distance as cone_apex_distance
from lagjax.rigid.solids import solid_cone_inertia as solid_cone_inertia
from lagjax.rigid.solids import solid_cylinder_inertia as solid_cylinder_inertia
from lagjax.rigid.solids import solid_sphere_inertia as solid_sphere_inertia
from lagjax.rigid.solids import spherical_shell_inertia as spherical_shell_inertia
from lagjax.rigid.solids import thin_disc_inertia as thin_disc_inertia
from lagjax.rigid.solids import thin_rod_inertia as thin_rod_inertia
