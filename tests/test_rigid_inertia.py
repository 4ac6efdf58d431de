"""Inertia tensors: point masses, standard solids, the axis theorems, principal axes.

The solids are checked against an independent computation: each body is replaced by
point masses at Gauss quadrature nodes (exact for the polynomial integrands), whose
tensor `point_mass_inertia` sums.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from lagjax.rigid import (
    axis_angle_quaternion,
    box_inertia,
    centre_of_mass,
    cone_apex_distance,
    parallel_axis,
    perpendicular_axis,
    point_mass_inertia,
    principal_axes,
    quaternion_to_matrix,
    solid_cone_inertia,
    solid_cylinder_inertia,
    solid_sphere_inertia,
    spherical_shell_inertia,
    thin_disc_inertia,
    thin_rod_inertia,
    top_kind,
)

MASS, RADIUS, HEIGHT = 2.5, 0.7, 1.9


def _gauss(n, lower, upper):
    nodes, weights = np.polynomial.legendre.leggauss(n)
    half = 0.5 * (upper - lower)
    return lower + half * (nodes + 1), half * weights


def _solid_of_revolution(max_radius, z_lower, z_upper, mass):
    """Quadrature point masses of a uniform solid of revolution about z."""
    angles = np.linspace(0, 2 * np.pi, 7, endpoint=False)
    s_nodes, s_weights = _gauss(5, 0.0, 1.0)
    if z_lower == z_upper:  # a lamina
        z_nodes, z_weights = np.array([z_lower]), np.array([1.0])
    else:
        z_nodes, z_weights = _gauss(8, z_lower, z_upper)
    masses, points = [], []
    for z, wz in zip(z_nodes, z_weights):
        r_max = max_radius(z)
        for s, ws in zip(s_nodes, s_weights):
            for angle in angles:
                # dm ∝ r dr dφ dz with r = s·r_max(z)
                masses.append(wz * ws * s * r_max**2)
                points.append([s * r_max * np.cos(angle), s * r_max * np.sin(angle), z])
    masses = np.array(masses)
    return jnp.asarray(mass * masses / masses.sum()), jnp.asarray(np.array(points))


def _about_centre(masses, points):
    return point_mass_inertia(masses, points - centre_of_mass(masses, points))


def test_point_masses_follow_the_definition():
    masses = jnp.array([1.0, 1.0, 3.0])
    points = jnp.array([[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [1.0, 1.0, 0.0]])
    inertia = point_mass_inertia(masses, points)
    # I_xx = Σ m(y² + z²) = 3, I_zz = Σ m(x² + y²) = 2 + 6, I_xy = −Σ m x y = −3.
    expected = jnp.array([[3.0, -3.0, 0.0], [-3.0, 5.0, 0.0], [0.0, 0.0, 8.0]])
    assert np.allclose(inertia, expected, atol=1e-14)


def test_point_masses_reject_bad_shapes():
    with pytest.raises(ValueError, match=r"shape \(n, 3\)"):
        point_mass_inertia(jnp.ones(2), jnp.ones((2, 2)))
    with pytest.raises(ValueError, match="masses must have shape"):
        point_mass_inertia(jnp.ones(3), jnp.ones((2, 3)))


@pytest.mark.parametrize(
    "name, formula, shape",
    [
        ("cylinder", solid_cylinder_inertia(MASS, RADIUS, HEIGHT), lambda z: RADIUS),
        (
            "sphere",
            solid_sphere_inertia(MASS, RADIUS),
            lambda z: np.sqrt(RADIUS**2 - z**2),
        ),
        (
            "cone",
            solid_cone_inertia(MASS, RADIUS, HEIGHT),
            lambda z: RADIUS * z / HEIGHT,
        ),
    ],
)
def test_solids_of_revolution_match_quadrature(name, formula, shape):
    z_range = (-RADIUS, RADIUS) if name == "sphere" else (0.0, HEIGHT)
    masses, points = _solid_of_revolution(shape, *z_range, MASS)
    assert np.allclose(_about_centre(masses, points), formula, rtol=1e-12, atol=1e-14)


def test_box_rod_disc_and_shell_match_quadrature():
    nodes, weights = _gauss(3, -0.5, 0.5)
    edges = np.array([0.3, 1.1, 2.0])
    grid = np.stack(np.meshgrid(nodes, nodes, nodes, indexing="ij"), -1).reshape(-1, 3)
    box_masses = MASS * np.einsum("i,j,k->ijk", weights, weights, weights).ravel()
    assert np.allclose(
        point_mass_inertia(box_masses, grid * edges),
        box_inertia(MASS, *edges),
        rtol=1e-13,
    )
    z, wz = _gauss(3, -HEIGHT / 2, HEIGHT / 2)
    rod = point_mass_inertia(MASS * wz / HEIGHT, np.stack([0 * z, 0 * z, z], -1))
    assert np.allclose(rod, thin_rod_inertia(MASS, HEIGHT), rtol=1e-13, atol=1e-14)
    masses, points = _solid_of_revolution(lambda z: RADIUS, 0.0, 0.0, MASS)
    assert np.allclose(_about_centre(masses, points), thin_disc_inertia(MASS, RADIUS))
    # A shell: uniform area measure d(cos θ) dφ.
    cosines, w_cos = _gauss(6, -1.0, 1.0)
    phis = np.linspace(0, 2 * np.pi, 7, endpoint=False)
    sines = np.sqrt(1 - cosines**2)
    shell = np.array(
        [
            [s * np.cos(f), s * np.sin(f), c]
            for c, s in zip(cosines, sines)
            for f in phis
        ]
    )
    shell_masses = MASS * np.repeat(w_cos, len(phis)) / (2 * len(phis))
    assert np.allclose(
        point_mass_inertia(shell_masses, RADIUS * shell),
        spherical_shell_inertia(MASS, RADIUS),
        rtol=1e-13,
    )


def test_parallel_axis_theorem_on_random_points():
    key_m, key_x, key_d = jax.random.split(jax.random.key(0), 3)
    masses = jax.random.uniform(key_m, (9,), minval=0.5, maxval=2.0)
    points = jax.random.normal(key_x, (9, 3))
    centred = points - centre_of_mass(masses, points)
    displacement = jax.random.normal(key_d, (3,))
    direct = point_mass_inertia(masses, centred - displacement)
    shifted = parallel_axis(
        point_mass_inertia(masses, centred), masses.sum(), displacement
    )
    assert np.allclose(direct, shifted, rtol=1e-13, atol=1e-13)


def test_cone_about_its_apex():
    # Goldstein's value for a cone spinning on its apex: 3M(R²/20 + h²/5).
    apex = parallel_axis(
        solid_cone_inertia(MASS, RADIUS, HEIGHT),
        MASS,
        jnp.array([0.0, 0.0, cone_apex_distance(HEIGHT)]),
    )
    transverse = 3 * MASS * (RADIUS**2 / 20 + HEIGHT**2 / 5)
    assert np.allclose(jnp.diag(apex), [transverse, transverse, 0.3 * MASS * RADIUS**2])


def test_perpendicular_axis_theorem_on_a_lamina():
    points = jax.random.normal(jax.random.key(1), (7, 3)).at[:, 2].set(0.0)
    masses = jnp.linspace(1.0, 2.0, 7)
    inertia = point_mass_inertia(masses, points)
    assert np.isclose(perpendicular_axis(inertia[0, 0], inertia[1, 1]), inertia[2, 2])
    disc = thin_disc_inertia(MASS, RADIUS)
    assert np.isclose(perpendicular_axis(disc[0, 0], disc[1, 1]), disc[2, 2])


def _rotated(moments, key):
    axis = jax.random.normal(key, (3,))
    q = axis_angle_quaternion(axis / jnp.linalg.norm(axis), 1.234)
    rotation = quaternion_to_matrix(q)
    return rotation @ jnp.diag(jnp.asarray(moments)) @ rotation.T, rotation


@pytest.mark.parametrize(
    "moments, kind",
    [
        ((1.0, 2.0, 3.0), "asymmetric"),
        ((2.0, 2.0, 5.0), "symmetric"),
        ((1.0, 4.0, 4.0), "symmetric"),
        ((3.0, 3.0, 3.0), "spherical"),
    ],
)
def test_principal_axes_diagonalise_and_classify(moments, kind):
    inertia, rotation = _rotated(moments, jax.random.key(2))
    found, axes = principal_axes(inertia)
    assert np.allclose(found, moments, rtol=1e-13)
    assert np.allclose(axes.T @ axes, np.eye(3), atol=1e-14)
    assert np.isclose(jnp.linalg.det(axes), 1.0)
    assert np.allclose(axes.T @ inertia @ axes, np.diag(moments), atol=1e-13)
    if (
        kind == "asymmetric"
    ):  # distinct moments: the axes are the rotation's, up to sign
        assert np.allclose(jnp.abs(jnp.sum(axes * rotation, axis=0)), 1.0)
    assert top_kind(found) == kind


def test_top_kind_tolerance_and_trace_time_error():
    assert top_kind(jnp.array([2.0, 2.0 * (1 + 1e-12), 5.0])) == "symmetric"
    assert top_kind(jnp.array([2.0, 2.0 * (1 + 1e-6), 5.0])) == "asymmetric"
    with pytest.raises(ValueError, match="concrete moments"):
        jax.jit(top_kind)(jnp.ones(3))
