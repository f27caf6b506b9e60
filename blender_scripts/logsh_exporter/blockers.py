"""Sphere blockers for one mesh: a set of spheres whose union approximates the mesh's
volume, so that the solid angle a receiver sees of the spheres is close to what it sees
of the mesh (docs/design.md, "Blocker proxies").

Pure numpy, no bpy: the exporter hands in world-space triangles and a sample of the
volume around the mesh (points with an inside flag and, inside, the distance to the
surface), found with Blender's BVH.

- **Objective.** The volume of the symmetric difference between the union of spheres and
  the mesh's interior, estimated on the volume sample (uniform random points over the
  mesh's bounding box grown by a quarter), relative to the mesh's volume. This is the
  error measure of the variational sphere-set approximation (Wang et al. 2006,
  "Variational Sphere Set Approximation for Solid Objects", which paper 000 cites as
  [WZS*06]): a sphere set that both leaves out and adds volume is penalised for both.
  Enclosing spheres (the previous fit) only ever add, 12 to 25 % of an object's size
  beyond it, and darkened every shadow.
- **Greedy growth.** Candidates are balls inscribed at sampled interior points (radius
  the distance to the surface) and the same balls grown by 10 to 50 %. Each step adds
  the candidate that lowers the objective most, until the error falls below the target
  (`error_target`, 0.1 by default) or a step gains less than 1 % of the volume, or the
  count reaches `max_count`.
- **Lloyd refinement** (WZS*06's alternation): each interior point goes to the sphere
  nearest it by power distance `|x - c| - r`; each centre moves to its points' centroid
  and each radius is chosen by a 1-D search minimising the objective; three rounds.
  Moves that raise the objective are undone.
- A mesh that one sphere approximates within the target is one sphere, of the mesh's
  exact volume and centroid (divergence theorem): a UV sphere becomes one sphere within 1 % of its
  radius (`tests/blender.rs`).
- **Coherence.** The fit is made once per mesh (on the first frame it is seen) in the
  object's local space. Later frames move it with the object's transform while the
  evaluated local mesh stays the same (rigid animation: exact), and fit anew when it
  deforms.
"""
import zlib

import numpy as np

# Relative volume error at which a fit stops adding spheres.
ERROR_TARGET = 0.1
# Growth factors of the candidate balls over the inscribed radius.
GROWTH = (1.0, 1.1, 1.2, 1.35, 1.5)
# Interior points tried as candidate centres.
CANDIDATES = 300
# A step must remove at least this fraction of the mesh's volume from the error.
MIN_GAIN = 0.01


def mesh_moments(triangles):
    """Volume and centroid of a closed triangle mesh (divergence theorem: the signed
    tetrahedra from the origin to each triangle), whichever way it is oriented."""
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    signed = np.einsum("ij,ij->i", a, np.cross(b, c)) / 6.0
    volume = float(signed.sum())
    if volume == 0.0:
        return 0.0, triangles.reshape(-1, 3).mean(axis=0)
    centroid = ((a + b + c) / 4.0 * signed[:, None]).sum(axis=0) / volume
    return abs(volume), centroid


def sample_box(triangles, count, seed):
    """`count` uniform random points over the mesh's bounding box grown by a quarter of
    its size on every side, and the box's volume."""
    vertices = triangles.reshape(-1, 3)
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    pad = 0.25 * (hi - lo) + 1e-6 * max(float(np.max(hi - lo)), 1e-9)
    lo, hi = lo - pad, hi + pad
    rng = np.random.default_rng(seed)
    return lo + rng.random((count, 3)) * (hi - lo), float(np.prod(hi - lo))


class VolumeFit:
    """Spheres approximating a volume sample: `points` (N, 3), `inside` (N,) booleans,
    `depth` (N,) distance to the surface (used at inside points), `point_volume` the
    volume each point stands for."""

    def __init__(self, name, points, inside, depth, point_volume, count=None, error_target=ERROR_TARGET,
                 max_count=16, moments=None):
        self.name = name
        inner = points[inside]
        if len(inner) < 8:
            raise ValueError(f"object \"{name}\" encloses no volume to fit blocker spheres to "
                             "(is it open or flat? give it a logsh_spheres property of 0 to skip it)")
        self.points, self.inside = points, inside
        self.volume = inside.sum() * point_volume
        rng = np.random.default_rng(zlib.crc32(name.encode()))
        pick = rng.choice(len(inner), size=min(CANDIDATES, len(inner)), replace=False)
        deep = np.argsort(-depth[inside])[:max(1, CANDIDATES // 10)]  # the deepest points too
        chosen = np.unique(np.concatenate([pick, deep]))
        self._candidate_centres = inner[chosen]
        base = np.maximum(depth[inside][chosen], 1e-9)
        self._candidate_radii = base[:, None] * np.array(GROWTH)[None]  # (centre, growth)
        wanted = count if count is not None else max_count
        self.centres, self.radii = self._greedy(wanted, None if count is not None else error_target)
        self._refine()
        if count is None:
            self._prune(error_target)
        if len(self.radii) == 1 and moments is not None and moments[0] > 0.0:
            # One sphere: the mesh's exact volume and centroid, which the sample only
            # estimates (a UV sphere of 32 x 16 segments: 0.995 of its radius).
            volume, centroid = moments
            equivalent = (3.0 * volume / (4.0 * np.pi)) ** (1.0 / 3.0)
            self.radii[0] = float(np.clip(equivalent, 0.8 * self.radii[0], 1.25 * self.radii[0]))
            if np.linalg.norm(centroid - self.centres[0]) <= 0.25 * self.radii[0]:
                self.centres[0] = centroid
        self.error = self.objective(self.centres, self.radii)

    # -- objective -----------------------------------------------------------------------

    def _covered(self, centres, radii):
        d2 = ((self.points[:, None, :] - centres[None]) ** 2).sum(axis=2)
        return (d2 <= radii[None] ** 2).any(axis=1)

    def objective(self, centres, radii):
        """Relative volume of the symmetric difference of the union and the mesh."""
        covered = self._covered(centres, radii)
        return float((covered != self.inside).sum()) / max(int(self.inside.sum()), 1)

    # -- greedy growth -------------------------------------------------------------------

    def _greedy(self, wanted, target):
        inside = self.inside
        total = max(int(inside.sum()), 1)
        d2 = ((self._candidate_centres[:, None, :] - self.points[None]) ** 2).sum(axis=2)
        growths = self._candidate_radii.shape[1]
        member = (d2[:, None, :] <= self._candidate_radii[:, :, None] ** 2).reshape(-1, len(self.points))
        sign = np.where(inside, 1, -1).astype(np.int32)
        covered = np.zeros(len(self.points), dtype=bool)
        chosen = []
        error = 1.0
        while len(chosen) < wanted:
            fresh = member & ~covered[None]
            gain = (fresh * sign[None]).sum(axis=1) / total
            best = int(np.argmax(gain))
            if chosen and (gain[best] < MIN_GAIN and target is not None):
                break
            if gain[best] <= 0 and chosen:
                break
            chosen.append(best)
            covered |= member[best]
            error = float((covered != inside).sum()) / total
            if target is not None and error <= target:
                break
        chosen = np.array(chosen, dtype=int)
        return self._candidate_centres[chosen // growths].copy(), self._candidate_radii.reshape(-1)[chosen].copy()

    # -- Lloyd refinement ----------------------------------------------------------------

    def _refine(self, rounds=3):
        self.centres, self.radii, _ = self._refined(self.centres, self.radii, rounds)

    def _refined(self, centres, radii, rounds):
        """Lloyd rounds from `(centres, radii)`; returns the best set met and its error."""
        inner = self.points[self.inside]
        best = (centres, radii, self.objective(centres, radii))
        for _ in range(rounds):
            centres, radii = best[0].copy(), best[1].copy()
            power = np.linalg.norm(inner[:, None, :] - centres[None], axis=2) - radii[None]
            owner = np.argmin(power, axis=1)
            for k in range(len(centres)):
                members = inner[owner == k]
                if len(members):
                    centres[k] = members.mean(axis=0)
            for k in range(len(centres)):
                radii[k] = self._best_radius(centres, radii, k)
            error = self.objective(centres, radii)
            if error >= best[2]:
                break
            best = (centres, radii, error)
        return best

    def _best_radius(self, centres, radii, k):
        """The radius of sphere `k` minimising the objective, the others fixed: the sorted
        distances of the points give the objective at every radius at once."""
        others = np.delete(np.arange(len(centres)), k)
        rest = self._covered(centres[others], radii[others]) if len(others) else np.zeros(len(self.points), bool)
        free = ~rest
        distance = np.linalg.norm(self.points[free] - centres[k], axis=1)
        order = np.argsort(distance)
        # Growing the radius past a free point adds +1 error if it is outside, -1 if inside.
        steps = np.where(self.inside[free][order], -1, 1)
        cumulative = np.concatenate([[0], np.cumsum(steps)])
        limit = np.searchsorted(distance[order], 2.0 * radii[k])
        best = int(np.argmin(cumulative[:limit + 1]))
        if best == 0:
            return 0.5 * distance[order][0] if len(order) else radii[k]
        return float(distance[order][best - 1])

    def _prune(self, target):
        """Drops a sphere whenever the others, refined, stay within the target or do no
        worse: greedy growth from off-centre candidates can leave two spheres where one
        does."""
        current = self.objective(self.centres, self.radii)
        while len(self.radii) > 1:
            for k in np.argsort(self.radii)[:8]:
                keep = np.delete(np.arange(len(self.radii)), k)
                centres, radii = self.centres[keep], self.radii[keep]
                error = self.objective(centres, radii)
                if error > max(target, current) and len(keep) <= 3:  # refining is worth it for few
                    centres, radii, error = self._refined(centres, radii, 2)
                if error <= max(target, current):
                    self.centres, self.radii, current = centres, radii, error
                    break
            else:
                break
        self._refine()


class ObjectSpheres:
    """The fit of one object, kept in its local space and moved with it across frames."""

    def __init__(self, name, fit, matrix, local_vertices):
        self.name = name
        self.count = len(fit.radii)
        self.error = fit.error
        inverse = np.linalg.inv(matrix)
        self.local_centres = fit.centres @ inverse[:3, :3].T + inverse[:3, 3]
        self.scale = _scale(matrix)
        self.local_radii = fit.radii / self.scale
        self.local_vertices = local_vertices

    def follows(self, local_vertices):
        """True while the evaluated mesh has not deformed (the fit moves rigidly)."""
        return local_vertices.shape == self.local_vertices.shape and np.allclose(
            local_vertices, self.local_vertices, rtol=0.0, atol=1e-6 * (1.0 + np.abs(self.local_vertices).max()))

    def spheres(self, matrix):
        """World centres (k, 3) and radii (k,) under the object's world `matrix`."""
        m = np.asarray(matrix)
        return self.local_centres @ m[:3, :3].T + m[:3, 3], self.local_radii * _scale(m)


def _scale(matrix):
    """The mean scale of a transform (cube root of its linear part's determinant)."""
    return abs(float(np.linalg.det(np.asarray(matrix)[:3, :3]))) ** (1.0 / 3.0)
