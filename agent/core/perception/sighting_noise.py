"""The measured noise of a sighting: what a neighbour record's entries are worth
(NAO paper 3.2, eqs. 6-8: distance from the D-base, bearing from the pixel and the
compass; 3.1.2: the mask orientation of the M-base), as fitted on rendered records with
their truth (``python -m tools.fit_noise``, from the corpus of ``python -m tools.corpus``).

A sighting ``v_ij`` of robot i, in its fixed frame, at true distance d from j:

* **distance error** (along the line of sight): Gaussian,
  ``σ_r(d)² = r0² + (r_lin·d)² + (r1·d²)²`` (a floor, and the distance's own error: it
  comes from the mask's size in the image, eq. 6, which shrinks as 1/d, so a pixel's
  error costs ∝ d²; independent errors add in variance; ``r_lin``, a relative error, is
  0 for the rendered perception and serves synthetic records, :meth:`SightingNoise.synthetic`);
* **error across the line of sight** (in metres at the target): Gaussian,
  ``σ_t(d)² = t0² + (t_lin·d)² + (t1·d²)²`` (the bearing of a pixel and the compass's
  heading, and the fit's own spread, which grows with the lever arm);
* **rejected pairs**: gross errors happen (two NAOs merged into one detection, a NAO
  half hidden, a sighting paired with the wrong robot), and the heavy tail of the
  errors above is not Gaussian: the rate at which the fleet's χ² test of its fitted
  frame rejects a pair of *sound* robots at distance d is
  ``p_reject(d) = clip(g0 + g1·d, P_MIN, P_MAX)``, measured with that very test on
  fault-free fleets;
* **lost strays**: a sighting of a sound robot ends up one that no pair explains and
  that lands on no robot within the χ² gate of the fitted frame (a ghost or merged
  detection) with probability ``p_stray(d) = clip(s0 + s1·d, P_MIN, P_MAX)`` per
  sighting, measured like ``p_reject``;
* **lost when tested alone**: a sound robot's sighting lands on no other robot, once the
  robot is placed where the others saw it and turned to the heading under which most of
  its sightings land, with the others held at their fitted poses
  (:func:`agent.core.formation.frame.faults.alone.alone_test`), with probability
  ``p_alone(d) = clip(a0, P_MIN, P_MAX)`` per sighting, measured with that very test on
  fault-free fleets. It is not ``p_stray``: a sighting that pairs in the fit (a wrong
  pairing, a merged detection counted among the rejected pairs) is tested here like any
  other, so this rate holds both kinds (on the shipped corpus, four times ``p_stray``);
* **mask orientation** θ_ij (the relative orientation of the matched mask, known modulo π):
  its error modulo π is ``N(0, σ_m)`` with probability ``w0``, the side/front confusion
  ``N(±π/2, σ_m)`` with ``w90``, otherwise uniform (front/back, 180°, is folded away by
  the modulo);
* **front/back confusion**: a mask turned back to its target's start heading (its record
  carries times: docs/design.md §9 "Masks seen mid-turn") reads the NAO the other way
  round, its error modulo 2π beyond ±90°, with a probability that depends on what the
  mask itself read: ``reversal(θ)``, the rate ``w180_view`` measured among the masks whose
  |θ| as the camera read it (before the turn-back) falls in the same 30° bin. A NAO read
  from the front is seldom read the other way round (5 % within 30° of facing the
  camera, on the shipped corpus); one read from behind is more often a front view than
  not (59 % beyond 150°): the shape of a NAO's back and of its front differ less than
  the caps' layout. ``w180`` is the rate over every mask (22 %), used for a mask with
  no reading and by a model without bins. Masks are independent given their readings;
  over the full circle a mask error δ then has the density ``f(δ)·(1 − q)`` within
  ±90° and ``f(δ)·q`` beyond, f the density modulo π and q its reversal rate. A mask of
  a record without times says nothing of front and back (its target may have turned
  half round in its own search: on the corpus, read as recorded, 52 % are the other way
  round);
* **a robot seen turned as a whole**: with probability ``rho`` the others' masks of a
  *sound* robot all agree on an offset that the per-mask model above cannot explain (a
  bias of the masks for that robot's aspect, say). A broken compass looks exactly the
  same from outside (the robot's own sightings turn, its fitted ψ with them, and the
  others' masks disagree with it by one offset), so no mask evidence can call a robot
  faulty with a false-alarm rate below ``rho``. The masks are those turned back to the
  robot's start heading by the records' times (a mask of a robot seen while it turned in
  its own search set aside: docs/design.md §9 "Masks seen mid-turn"); ``rho_untimed`` is
  the rate for records without times, where a robot seen mid-turn is seen turned as a
  whole (measured on the corpus of such records at 7.7 %);
* **a sensor bias** (a robot's distances scaled, or its sightings shifted, all alike):
  the likelihood-ratio statistic Λ of :mod:`agent.core.formation.frame.faults.bias_test` over a
  sound robot's sightings, divided by ``bias_scale``, follows χ² with three degrees of
  freedom in its tail (Wilks, for a model this one describes): ``bias_scale`` is that
  ratio, measured on fault-free fleets and never below 1.

The fault test of the common frame (:mod:`agent.core.formation.frame.faults.fault_test`) uses
it: a sighting's normalised residual is χ² with two degrees of freedom under this model,
and ``p_reject`` is the base rate of its per-robot count of rejected pairs.

The parameters ship in ``agent/core/perception/data/sighting_noise.json`` beside the
M-base and D-base, with the corpus they were fitted on.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from agent.core.perception.mbase import DATA_DIR

FORMAT = 1
P_MIN = 1e-3  #: the smallest rejection rate the model admits (a pair can always be wrong)
#: The bins of a mask's reading |θ| (rad) for its front/back confusion (``w180_view``)
VIEW_BIN = math.pi / 6
VIEW_BINS = 6
P_MAX = 0.5  #: the largest (beyond it a sighting carries no information)


@dataclass(frozen=True)
class SightingNoise:
    """The fitted noise model (module docstring); lengths in metres, angles in radians."""

    r0: float
    r1: float
    t0: float
    t1: float
    g0: float
    g1: float
    sigma_mask: float
    w0: float
    w90: float
    rho: float = 0.0  #: rate of sound robots seen turned as a whole (module docstring)
    #: the same rate for a robot whose record carries no times (module docstring)
    rho_untimed: float = 0.0
    s0: float = 0.0
    s1: float = 0.0
    #: the rate of a sound robot's sightings lost when it is tested alone (module docstring)
    a0: float = 0.0
    r_lin: float = 0.0
    t_lin: float = 0.0
    #: the bias test's null scale: Λ / bias_scale is χ²₃ in its tail on sound robots
    #: (measured; module docstring)
    bias_scale: float = 1.0
    #: the heading test's null scale: Wilks' statistic / mask_scale is χ²₁ in its tail on
    #: sound robots whose records carry times (measured; module docstring)
    mask_scale: float = 1.0
    #: front/back confusion: the share of masks turned back to their target's start
    #: heading that read it the other way round (module docstring); ½ says nothing
    w180: float = 0.5
    #: front/back confusion by the mask's own reading: the share read the other way round
    #: among the masks whose |θ| as read falls in each :data:`VIEW_BIN` (0–30°, …,
    #: 150–180°); empty: ``w180`` for every mask (module docstring)
    w180_view: tuple[float, ...] = ()
    sightings: int = 0  #: how many matched sightings it was fitted on
    corpus: str = ""  #: which corpus (and split) it was fitted on

    def __post_init__(self) -> None:
        for name in (
            "r0",
            "r1",
            "t0",
            "t1",
            "g0",
            "g1",
            "sigma_mask",
            "w0",
            "w90",
            "rho",
            "rho_untimed",
            "s0",
            "s1",
            "a0",
        ):
            v = getattr(self, name)
            if not math.isfinite(v):
                raise ValueError(f"sighting noise {name} must be finite, got {v}")
        if self.r0 <= 0 or self.t0 <= 0 or min(self.r1, self.t1, self.r_lin, self.t_lin) < 0:
            raise ValueError("sighting noise: r0, t0 must be > 0 and r1, t1, r_lin, t_lin >= 0")
        if not 0 < self.sigma_mask < math.pi / 4:
            raise ValueError(f"sigma_mask must be in (0, π/4), got {self.sigma_mask}")
        for name in ("rho", "rho_untimed", "w180"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"{name} must be in [0, 1], got {getattr(self, name)}")
        object.__setattr__(self, "w180_view", tuple(float(q) for q in self.w180_view))
        if len(self.w180_view) not in (0, VIEW_BINS):
            raise ValueError(
                f"w180_view holds {len(self.w180_view)} rates, expected 0 or {VIEW_BINS}"
            )
        if not all(0.0 <= q <= 1.0 for q in self.w180_view):
            raise ValueError(f"w180_view rates must be in [0, 1], got {self.w180_view}")
        for name in ("bias_scale", "mask_scale"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0.0):
                raise ValueError(f"{name} must be finite and > 0, got {v}")
        if not (0 <= self.w0 <= 1 and 0 <= self.w90 <= 1 and self.w0 + self.w90 <= 1):
            raise ValueError(f"mask weights w0={self.w0}, w90={self.w90} must be a distribution")

    def sigma_radial(self, d: np.ndarray | float) -> np.ndarray:
        """σ of the distance (m) at true distance ``d``."""
        x = np.asarray(d, dtype=np.float64)
        return np.asarray(np.sqrt(self.r0**2 + (self.r_lin * x) ** 2 + (self.r1 * x**2) ** 2))

    def sigma_tangential(self, d: np.ndarray | float) -> np.ndarray:
        """σ across the line of sight (m) at distance ``d``."""
        x = np.asarray(d, dtype=np.float64)
        return np.asarray(np.sqrt(self.t0**2 + (self.t_lin * x) ** 2 + (self.t1 * x**2) ** 2))

    def p_reject(self, d: np.ndarray | float) -> np.ndarray:
        """Probability that the χ² test rejects a pair of sound robots at distance ``d``."""
        p = self.g0 + self.g1 * np.asarray(d, dtype=np.float64)
        return np.asarray(np.clip(p, P_MIN, P_MAX))

    def p_stray(self, d: np.ndarray | float) -> np.ndarray:
        """Probability that a sound robot's sighting at ``d`` ends up a lost stray."""
        p = self.s0 + self.s1 * np.asarray(d, dtype=np.float64)
        return np.asarray(np.clip(p, P_MIN, P_MAX))

    def p_alone(self, d: np.ndarray | float) -> np.ndarray:
        """Probability that a sound robot's sighting at ``d`` lands on no robot when the
        robot is tested alone against the others (module docstring)."""
        p = self.a0 + 0.0 * np.asarray(d, dtype=np.float64)
        return np.asarray(np.clip(p, P_MIN, P_MAX))

    def chi2(self, vector: np.ndarray, error: np.ndarray) -> np.ndarray:
        """Normalised squared residual (χ², 2 degrees of freedom) of ``error`` (k, 2), the
        misfit of sightings ``vector`` (k, 2), both in the owner's fixed frame: split along
        and across each line of sight and divided by σ_r, σ_t at the sighting's distance."""
        d, along, across = split(vector, error)
        return np.asarray(
            (along / self.sigma_radial(d)) ** 2 + (across / self.sigma_tangential(d)) ** 2
        )

    def reversal(self, view: float) -> float:
        """The probability that a sound mask read as ``view`` (rad, θ as the camera read
        it, before any turn-back) reads its target the other way round: ``w180_view`` of
        its bin of |θ|, or ``w180`` for a mask without a reading (nan) or a model without
        bins; clipped to [P_MIN, 1 − P_MIN], so that no one mask is ever certain."""
        k = view_bin(view)
        q = self.w180_view[k] if self.w180_view and k is not None else self.w180
        return min(max(q, P_MIN), 1.0 - P_MIN)

    def mask_density(self, delta: np.ndarray | float) -> np.ndarray:
        """Density (per radian, over a period of π) of a mask error ``delta`` modulo π."""
        x = np.asarray(delta, dtype=np.float64)
        x = (x + math.pi / 2) % math.pi - math.pi / 2
        s = self.sigma_mask
        norm = 1.0 / (s * math.sqrt(2 * math.pi))

        def bump(c: float) -> np.ndarray:  # wrapped: the nearest copy of c modulo π
            y = (x - c + math.pi / 2) % math.pi - math.pi / 2
            return np.asarray(norm * np.exp(-0.5 * (y / s) ** 2))

        uniform = (1.0 - self.w0 - self.w90) / math.pi
        return np.asarray(self.w0 * bump(0.0) + self.w90 * bump(math.pi / 2) + uniform)

    @classmethod
    def synthetic(cls, floor: float, relative: float = 0.0, bearing: float = 0.0) -> SightingNoise:
        """The model of synthetic records whose sightings carry uniform noise: ±``relative``
        of the distance, ±``bearing`` (rad) across, and a disc of radius 2·``floor`` (σ of
        each: the bound / √3, and floor = R/2 for the disc); no gross errors, and masks as
        the shipped model's. For tests and the papers' Monte Carlo, whose noise is not the
        rendered perception's."""
        shipped = shipped_noise()
        third = 1.0 / math.sqrt(3.0)
        return cls(r0=floor, r1=0.0, t0=floor, t1=0.0, g0=0.0, g1=0.0,
                   sigma_mask=shipped.sigma_mask, w0=shipped.w0, w90=shipped.w90, rho=shipped.rho,
                   rho_untimed=shipped.rho_untimed, w180=shipped.w180,
                   w180_view=shipped.w180_view,
                   r_lin=relative * third, t_lin=bearing * third, corpus="synthetic")  # fmt: skip

    def save(self, directory: Path = DATA_DIR, stem: str = "sighting_noise") -> Path:
        path = Path(directory) / f"{stem}.json"
        doc = {"format": FORMAT, **asdict(self)}
        path.write_text(json.dumps(doc, indent=1, sort_keys=True) + "\n")
        return path

    @classmethod
    def load(cls, directory: Path | None = None, stem: str = "sighting_noise") -> SightingNoise:
        """The model in ``directory`` (default: the shipped one); ``ValueError`` when the
        file is of another format or a parameter is out of range."""
        path = (DATA_DIR if directory is None else Path(directory)) / f"{stem}.json"
        doc = json.loads(path.read_text())
        if doc.get("format") != FORMAT:
            raise ValueError(
                f"{path}: sighting noise format {doc.get('format')!r}, expected {FORMAT}"
            )
        doc.pop("format")
        return cls(**doc)


def view_bin(view: float) -> int | None:
    """The bin (0 … VIEW_BINS − 1) of a mask read as ``view`` (rad): its |θ| folded into
    [0, π] in steps of :data:`VIEW_BIN`, π itself in the last; None for no reading (nan)."""
    if not math.isfinite(view):
        return None
    return min(int(abs(math.remainder(view, 2 * math.pi)) / VIEW_BIN), VIEW_BINS - 1)


def split(vector: np.ndarray, error: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(distance, error along, error across) of misfits ``error`` (k, 2) of sightings
    ``vector`` (k, 2), both in the owner's fixed frame."""
    v = np.asarray(vector, dtype=np.float64).reshape(-1, 2)
    e = np.asarray(error, dtype=np.float64).reshape(-1, 2)
    d = np.hypot(v[:, 0], v[:, 1])
    u = v / np.maximum(d, 1e-9)[:, None]
    along = np.einsum("ij,ij->i", e, u)
    across = e[:, 1] * u[:, 0] - e[:, 0] * u[:, 1]
    return d, np.asarray(along), np.asarray(across)


@lru_cache(maxsize=1)
def shipped_noise() -> SightingNoise:
    """The model that ships with the agent (loaded once per process)."""
    return SightingNoise.load()
