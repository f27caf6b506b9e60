"""Sphere blockers for one mesh: k-means clusters of surface samples, radii that cover it.

Pure numpy, no bpy: the exporter hands in world-space triangles each frame.

- Samples: points spread uniformly over the surface (triangles drawn in proportion to
  their area, barycentric coordinates uniform), a fixed count per sphere. Each sample is
  kept as (triangle, barycentric coordinates), so that on later frames the same material
  points are found again on the deformed mesh.
- Clustering: Lloyd's k-means on the samples, seeded with k-means++ (each new seed drawn
  with probability proportional to its squared distance from the seeds so far), which
  spreads the seeds over the whole surface and avoids the empty or doubled clusters of a
  uniform random start; the generator is seeded from the object's name, so an export is
  reproducible. A cluster that empties is moved to the sample farthest from its centre.
- Coherence: clustering happens once, on the first frame a mesh is seen. Later frames
  keep each sample's cluster and only recompute centres and radii, so spheres follow the
  animation (armatures, modifiers, shape keys) instead of jumping between clusterings. A
  mesh whose triangle count changes is clustered anew.
- Radius: the largest distance from a sphere's centre to its samples and to the mesh
  vertices nearest to it, so that the union of spheres holds every sample and every
  vertex: light does not leak through a blocker between its spheres. Covering whole
  triangles instead would be exact, but a long, thin triangle (the side of a cone or a
  cylinder primitive) would then inflate its sphere to half the object. What the union
  misses between samples, and how far it reaches beyond the surface, is measured and
  printed as the fit error (`exporter.fit_error`).
"""
import zlib

import numpy as np


class SphereFit:
    """The clustering of one mesh, reused across frames while its topology holds."""

    def __init__(self, name, triangles, count, samples_per_sphere=40, iterations=25):
        """`triangles`: (T, 3, 3) world-space vertex positions; `count`: spheres wanted."""
        self.name = name
        self.triangle_count = len(triangles)
        rng = np.random.default_rng(zlib.crc32(name.encode()))
        area = _areas(triangles)
        if not np.isfinite(area).all() or area.sum() <= 0.0:
            raise ValueError(f"object \"{name}\" has no surface area to fit blocker spheres to")
        count = max(1, min(int(count), len(triangles)))
        n = max(count * samples_per_sphere, 64)
        self.sample_triangle = rng.choice(len(triangles), size=n, p=area / area.sum())
        u, v = rng.random(n), rng.random(n)
        flip = u + v > 1.0
        u[flip], v[flip] = 1.0 - u[flip], 1.0 - v[flip]
        self.sample_weights = np.stack([1.0 - u - v, u, v], axis=1)
        points = self._samples(triangles)
        centres = _kmeans_plus_plus(points, count, rng)
        for _ in range(iterations):
            label = _nearest(points, centres)
            moved = centres.copy()
            for k in range(count):
                members = points[label == k]
                if len(members):
                    moved[k] = members.mean(axis=0)
                else:
                    far = np.argmax(np.linalg.norm(points - centres[label], axis=1))
                    moved[k] = points[far]
            if np.allclose(moved, centres, atol=1e-9):
                break
            centres = moved
        self.sample_label = _nearest(points, centres)
        self.count = count

    def _samples(self, triangles):
        t = triangles[self.sample_triangle]
        return np.einsum("nk,nkd->nd", self.sample_weights, t)

    def fits(self, triangles):
        return len(triangles) == self.triangle_count

    def spheres(self, triangles):
        """Centres (k, 3) and radii (k,) for this frame's triangles."""
        points = self._samples(triangles)
        used = np.unique(self.sample_label)
        centres = np.array([points[self.sample_label == k].mean(axis=0) for k in used])
        label = np.searchsorted(used, self.sample_label)
        vertices = np.unique(triangles.reshape(-1, 3), axis=0)
        vertex_label = _nearest(vertices, centres)
        radii = np.zeros(len(centres))
        for k in range(len(centres)):
            held = np.concatenate([points[label == k], vertices[vertex_label == k]])
            radii[k] = np.linalg.norm(held - centres[k], axis=1).max()
        return centres, radii

    def surface_points(self, triangles, n=2000):
        """Fresh surface samples (not those clustered) for measuring coverage."""
        rng = np.random.default_rng(1)
        area = _areas(triangles)
        t = triangles[rng.choice(len(triangles), size=n, p=area / area.sum())]
        u, v = rng.random(n), rng.random(n)
        flip = u + v > 1.0
        u[flip], v[flip] = 1.0 - u[flip], 1.0 - v[flip]
        return t[:, 0] + u[:, None] * (t[:, 1] - t[:, 0]) + v[:, None] * (t[:, 2] - t[:, 0])


def fibonacci_sphere(n):
    """`n` nearly evenly spread unit vectors (the golden-angle spiral)."""
    i = np.arange(n) + 0.5
    z = 1.0 - 2.0 * i / n
    phi = np.pi * (1.0 + 5.0 ** 0.5) * i
    r = np.sqrt(1.0 - z * z)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def union_boundary_points(centres, radii, per_sphere=32):
    """Points on the boundary of the union of spheres (points of each sphere's surface
    that lie inside no other sphere); used to measure how far the union reaches out."""
    directions = fibonacci_sphere(per_sphere)
    points = (centres[:, None, :] + radii[:, None, None] * directions[None]).reshape(-1, 3)
    owner = np.repeat(np.arange(len(centres)), per_sphere)
    distance = np.linalg.norm(points[:, None, :] - centres[None], axis=2)
    inside_other = (distance < radii[None] * (1.0 - 1e-6)) & (owner[:, None] != np.arange(len(centres))[None])
    return points[~inside_other.any(axis=1)]


def _areas(triangles):
    return 0.5 * np.linalg.norm(np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0]), axis=1)


def _nearest(points, centres):
    d = ((points[:, None, :] - centres[None]) ** 2).sum(axis=2)
    return np.argmin(d, axis=1)


def _kmeans_plus_plus(points, k, rng):
    centres = [points[rng.integers(len(points))]]
    d2 = ((points - centres[0]) ** 2).sum(axis=1)
    for _ in range(1, k):
        total = d2.sum()
        index = rng.choice(len(points), p=d2 / total) if total > 0 else rng.integers(len(points))
        centres.append(points[index])
        d2 = np.minimum(d2, ((points - points[index]) ** 2).sum(axis=1))
    return np.array(centres)
