"""Plots (matplotlib is imported here only, never by `import jaxrock`)."""

import matplotlib.pyplot as plt
import numpy as np

from ._fit import PulseFit, _histories
from ._fragility import Fragility
from ._intensity import measure_attrs
from ._maps import BehaviorMap
from ._record import Record
from ._response_spectrum import ResponseSpectrum
from ._results import Outcome, Response, Status
from ._spectrum import OverturningSpectrum, linearized_overturning_amplitude

_COLOURS = {
    Outcome.NO_ROCKING: ("tab:blue", "No rocking"),
    Outcome.ROCKING: ("tab:green", "Rocking"),
    Outcome.OVERTURNED: ("tab:red", "Overturning"),
}
_MARKERS = {
    "uplift": ("^", "k"),
    "impact": ("v", "tab:orange"),
    "rest": ("s", "tab:gray"),
    "overturn": ("x", "tab:red"),
}


def response(resp: Response, axes=None):
    """Ground acceleration, base displacement and theta/alpha against time.

    Needs `simulate(..., history=True)`. Uplifts, impacts, rests and the
    overturn are marked on the theta/alpha curve, at the state just before
    each event (an overturn where the curve ends). Returns the figure.
    """
    h = resp.history
    if h is None:
        raise ValueError("`response` needs a history: simulate(..., history=True)")
    if axes is None:
        fig, axes = plt.subplots(3, 1, sharex=True, figsize=(8, 7))
    else:
        fig = axes[0].figure
    axes[0].plot(h.t, h.ground_acceleration / 9.81, "k", lw=1)
    axes[0].set_ylabel("ground acc. (g)")
    axes[1].plot(h.t, h.u * 100, "tab:purple", lw=1)
    axes[1].set_ylabel("base disp. u (cm)")
    rotation = h.theta / h.alpha
    axes[2].plot(h.t, rotation, "tab:green", lw=1)
    axes[2].set_ylabel("theta / alpha")
    for kind, (marker, colour) in _MARKERS.items():
        ts = np.array([t for t, k in zip(h.event_times, h.event_kinds) if k == kind])
        if ts.size:
            # On the curve: the row of the state just before the event (the
            # first of the two rows at its time), where an overturn ends it.
            rows = np.minimum(np.searchsorted(h.t, ts, side="left"), h.t.size - 1)
            axes[2].plot(
                ts, rotation[rows], marker, color=colour, ls="none", label=kind
            )
    if any(k in _MARKERS for k in h.event_kinds):
        axes[2].legend(loc="best", fontsize=8)
    axes[2].set_xlabel("t (s)")
    axes[0].set_title(resp.summary(), fontsize=8)
    fig.tight_layout()
    return fig


# Cells that are not SUCCESS: (colour, marker, label) by status (None: the
# failures).
_STATUS_MARKERS = {
    Status.SLIDING: ("tab:orange", "^", "slides"),
    Status.UNDECIDED: ("tab:gray", "+", "undecided"),
    Status.FREE_FLIGHT: ("tab:purple", "D", "leaves its base"),
    Status.CAPACITY_EXCEEDED: ("tab:brown", "s", "past capacity"),
    None: ("k", "x", "not converged"),
}


def behavior_map(bmap: BehaviorMap, ax=None, title: str | None = None):
    """The paper's behavior map: a dot per analysis over (lambda, r).

    Blue no rocking, green rocking, red overturning; cells whose block would
    slide (`Status.SLIDING`, a map with a `friction`) are orange triangles,
    undecided cells (`Status.UNDECIDED`) grey plus signs, cells whose ground
    fell faster than gravity (`Status.FREE_FLIGHT`) purple diamonds, cells
    whose isolator passed its capacity (`Status.CAPACITY_EXCEEDED`) brown
    squares, and
    cells whose analysis did not converge black crosses. Returns the axes.

    Draws one map (cells of shape (n_slenderness, n_size)). A map with batch
    axes (a batch of bases or motions, a suite of records) is refused with a
    `ValueError`: plot one member, `bmap.select(i)`, or all of them side by
    side, `compare_maps([bmap.select(i) for i in range(n)])`.
    """
    _check_one_map(bmap)
    if ax is None:
        _, ax = plt.subplots(figsize=(6, 5))
    lam, r = np.meshgrid(bmap.slenderness, bmap.size, indexing="ij")
    for code, (colour, label) in _COLOURS.items():
        sel = (bmap.outcome == code) & (bmap.status == 0)
        ax.scatter(lam[sel], r[sel], s=6, c=colour, label=label)
    for status, (colour, marker, label) in _STATUS_MARKERS.items():
        sel = bmap.status == status
        if status is None:
            sel = ~np.isin(bmap.status, [0, *(s for s in _STATUS_MARKERS if s)])
        if np.any(sel):
            ax.scatter(lam[sel], r[sel], s=12, c=colour, marker=marker, label=label)
    ax.set_xlabel("slenderness lambda = h/b")
    ax.set_ylabel("size r (m)")
    ax.set_title(title or f"{bmap.motion}\n{bmap.base}", fontsize=8)
    ax.legend(
        loc="upper center",
        bbox_to_anchor=(0.5, -0.13),
        ncol=4,
        fontsize=7,
        markerscale=2,
        frameon=False,
    )
    return ax


def _check_one_map(bmap: BehaviorMap, name: str = "bmap") -> None:
    """`ValueError` naming `name` unless `bmap` is one map (no batch axes),
    saying how to plot the members of a batch."""
    batch = np.shape(bmap.outcome)[:-2]
    if batch:
        dims = bmap.coordinates.dims if bmap.coordinates is not None else ()
        along = f" (axes: {', '.join(dims)})" if dims else ""
        n = batch[0]
        raise ValueError(
            f"`{name}` must be one map, got a batch of shape {batch}{along}: "
            f"plot one member, plot.behavior_map(bm.select(i)) for i in "
            f"0..{n - 1}, or all side by side, "
            f"plot.compare_maps([bm.select(i) for i in range({n})])"
        )


def compare_maps(maps, titles=None, columns: int | None = None):
    """Maps side by side, shared axes (fixed vs isolated, ...), `columns` to
    a row (default: all in one row). Each is one map (a member of a batch:
    `bm.select(i)`). Returns the figure."""
    maps = list(maps)
    for k, m in enumerate(maps):
        _check_one_map(m, f"maps[{k}]")
    titles = titles or [None] * len(maps)
    columns = columns or len(maps)
    rows = -(-len(maps) // columns)
    fig, axes = plt.subplots(
        rows,
        columns,
        figsize=(5.5 * columns, 5 * rows),
        sharex=True,
        sharey=True,
        squeeze=False,
    )
    for ax, m, t in zip(axes.ravel(), maps, titles):
        behavior_map(m, ax=ax, title=t)
    for ax in axes.ravel()[len(maps) :]:
        ax.set_visible(False)
    fig.tight_layout()
    return fig


def _im_label(measure: str) -> str:
    """An axis label of an intensity measure: its name and unit."""
    attrs = measure_attrs(measure)
    if attrs["units"] == "1":
        return attrs["long_name"]
    return f"{attrs['long_name']} ({attrs['units']})"


def fragility(frag: Fragility, ax=None, title: str | None = None):
    """Fragility curves: outcomes as points (0 or 1) and the lognormal fits.

    Without damage states: P(rocking) and P(overturning). With
    `fragility(..., damage_states=...)`: one curve per damage state, together,
    from the least to the most severe, each state's outcomes as points just
    above 1 or below 0. For a suite, the share of records that have
    overturned the block at or below each intensity (each record's lowest
    such scale).
    """
    if ax is None:
        _, ax = plt.subplots(figsize=(6, 4))
    im = np.asarray(frag.im)
    if frag.damage_states:
        cmap = plt.get_cmap("plasma")
        count = len(frag.damage_states)
        states = [
            (name, frag.exceeded[:, k], cmap(0.85 * k / max(count - 1, 1)), name)
            for k, name in enumerate(frag.damage_states)
        ]
    else:
        states = [
            ("rocking", frag.rocked, "tab:green", "rocked"),
            ("overturning", frag.overturned, "tab:red", "overturned"),
        ]
    # Each state's points a little apart, so that they do not hide each other.
    offsets = np.linspace(0.02, -0.02, len(states)) if len(states) > 1 else [0.0]
    for (which, reached, colour, label), offset in zip(states, offsets):
        ax.plot(
            im,
            reached + offset,
            "o",
            color=colour,
            ms=4,
            alpha=0.6,
            label=f"{label} (1) or not (0)",
        )
    if frag.motion_names is not None and frag.motion_index is not None:
        members = np.unique(frag.motion_index)
        first = np.array(
            [
                np.min(im[(frag.motion_index == m) & frag.overturned], initial=np.inf)
                for m in members
            ]
        )
        reached = np.sort(first[np.isfinite(first)])
        if reached.size:
            ax.step(
                np.r_[reached, im.max()],
                np.r_[np.arange(1, reached.size + 1), reached.size] / members.size,
                where="post",
                color="tab:red",
                lw=1.0,
                ls="--",
                label=f"records overturning at or below ({members.size} records)",
            )
    grid = np.geomspace(im[im > 0].min() / 1.5, im.max() * 1.5, 300)
    for which, _, colour, _ in states:
        median, beta = _fit_of(frag, which)
        if np.isfinite(median):
            ax.plot(
                grid,
                frag.probability(grid, which),
                color=colour,
                label=f"P({which}): median {median:.3g}, beta {beta:.2f}",
            )
    ax.set_xscale("log")
    ax.set_xlabel(_im_label(frag.measure))
    ax.set_ylabel("probability")
    ax.set_ylim(-0.08, 1.08)
    ax.legend(fontsize=7, loc="center right")
    if title:
        ax.set_title(title, fontsize=9)
    return ax


def _fit_of(frag: Fragility, which: str):
    """(median, beta) of the curve `which` of `frag`."""
    if which in ("rocking", "overturning"):
        return getattr(frag, f"median_{which}"), getattr(frag, f"beta_{which}")
    k = frag.damage_states.index(which)
    return frag.median_damage[k], frag.beta_damage[k]


def response_spectrum(spectra, labels=None, ax=None):
    """Pseudo-spectral acceleration against period, log-log.

    `spectra`: one `ResponseSpectrum` (each member of a batch drawn) or a
    list of them; `labels`: one per curve (default: the records' names).
    """
    if isinstance(spectra, ResponseSpectrum):
        spectra = [spectra]
    if ax is None:
        _, ax = plt.subplots(figsize=(6, 4))
    curves = []
    for s in spectra:
        psa = np.asarray(s.pseudo_acceleration).reshape(-1, s.periods.size)
        names = s.names if s.names is not None else (None,) * psa.shape[0]
        curves += [(s.periods, row, name) for row, name in zip(psa, names)]
    labels = labels or [name for *_, name in curves]
    for (periods, psa, _), label in zip(curves, labels):
        ax.plot(periods, psa, label=label)
    ax.set_xscale("log")
    # A log scale needs a positive value (a record of zeros has none).
    if any(np.any(psa > 0) for _, psa, _ in curves):
        ax.set_yscale("log")
    ax.set_xlabel("period T (s)")
    ax.set_ylabel(f"PSA (m/s^2), {spectra[0].damping:.0%} damping")
    if any(label is not None for label in labels):
        ax.legend(fontsize=7)
    return ax


def overturning_spectrum(spectra, labels=None, ax=None, linearized=True):
    """Overturning regions (dots) and their lower edges (lines) over omega_p / p.

    `spectra`: one `OverturningSpectrum` or several (e.g. fixed and isolated).
    Filled dots overturn without impact (Makris & Roussos's mode 2), open ones
    after impacts (mode 1). `linearized` adds the closed-form linearized edge of
    mode 2 (`linearized_overturning_amplitude`, slender fixed-base blocks).
    """
    if isinstance(spectra, OverturningSpectrum):
        spectra = [spectra]
    labels = labels or [s.base for s in spectra]
    if ax is None:
        _, ax = plt.subplots(figsize=(6, 4.5))
    for k, (s, label) in enumerate(zip(spectra, labels)):
        colour = f"C{k}"
        F, A = np.meshgrid(s.frequency_ratio, s.amplitude_ratio, indexing="ij")
        over = s.outcome == Outcome.OVERTURNED
        for mode, marker in ((s.impacts == 0, "o"), (s.impacts > 0, "x")):
            ax.scatter(
                F[over & mode],
                A[over & mode],
                s=8,
                color=colour,
                marker=marker,
                alpha=0.35,
            )
        ax.plot(
            s.frequency_ratio,
            s.minimum,
            "-",
            color=colour,
            lw=2,
            label=f"{label}: minimum overturning amplitude",
        )
    if linearized:
        xlim, ylim = ax.get_xlim(), ax.get_ylim()
        w = np.linspace(max(xlim[0], 1e-3), xlim[1], 50)
        ax.plot(
            w,
            linearized_overturning_amplitude(w),
            "k--",
            lw=1,
            label="no impact, linearized (Makris & Roussos)",
        )
        ax.set_xlim(xlim)
        ax.set_ylim(ylim)
    ax.set_xlabel("omega_p / p")
    ax.set_ylabel("a_p / (g tan alpha)")
    ax.set_title(
        "Overturning under a one-sine pulse (o: without impact, x: after impacts)",
        fontsize=9,
    )
    ax.legend(fontsize=7)
    return ax


def pulse_fit(record: Record, fit: PulseFit, axes=None):
    """A record and a pulse fitted to it (`fit_pulse`) in three panels:
    acceleration (m/s^2), velocity (m/s) and displacement (m) against time
    (s), the record in black, the pulse in red.

    The record's velocity is its trapezoid-rule integral less the baseline
    that `score_pulse` fits with the pulse (a least-squares line); the
    displacements are the trapezoid-rule integrals of the velocities, from
    zero. `axes`: three matplotlib axes to draw in (default: a new figure).
    Returns the figure.

    Examples:
        >>> import numpy as np, jaxrock as jr
        >>> from jaxrock import plot
        >>> pulse = jr.MPPulse(0.8, 0.6, 2.0, 60.0, t0=5.0)
        >>> t = np.arange(0.0, 12.0, 0.005)
        >>> rec = jr.Record(np.asarray(pulse.acceleration(t)), 0.005)
        >>> fig = plot.pulse_fit(rec, jr.score_pulse(rec, pulse))
        >>> [ax.get_ylabel() for ax in fig.axes]
        ['acceleration (m/s^2)', 'velocity (m/s)', 'displacement (m)']
    """
    h = _histories(record, fit.pulse)
    if axes is None:
        fig, axes = plt.subplots(3, 1, sharex=True, figsize=(8, 7))
    else:
        fig = axes[0].figure
    for ax, kind, unit in zip(
        axes,
        ("acceleration", "velocity", "displacement"),
        ("m/s^2", "m/s", "m"),
    ):
        ax.plot(h["t"], h[f"record_{kind}"], "k", lw=0.8, label="record")
        ax.plot(h["t"], h[f"pulse_{kind}"], "tab:red", lw=1.5, label="pulse")
        ax.set_ylabel(f"{kind} ({unit})")
    axes[0].legend(loc="upper right", fontsize=8)
    axes[2].set_xlabel("t (s)")
    axes[0].set_title(
        f"{record.name or 'record'}\n{fit.pulse.describe()}, t0 = "
        f"{float(fit.pulse.t0):.3g} s\ncorrelation {float(fit.correlation):.3f}, "
        f"energy share {float(fit.energy_share):.3f}",
        fontsize=8,
    )
    fig.tight_layout()
    return fig
