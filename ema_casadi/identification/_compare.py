"""Model selection: the same records and free parameters fitted with every combination
of structural options (``anti_windup = backcalc | clamping``, ``friction = smooth |
...``), ranked by the adequacy tests first and then by the Bayesian information
criterion.

BIC = -2 log L + k log N, with -2 log L = sum of the weighted squared residuals where
the noise levels were given, and sum_c N_c log(RSS_c / N_c) (the likelihood profiled
over one noise level per channel) where they were estimated; k free parameters, N
residuals. A lower BIC is better; a difference above 10 is decisive. An adequate
structure ranks before any inadequate one (a structure that cannot explain the
records is not rescued by its likelihood).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field

import numpy as np

from .._util._checks import nearest
from .._util._notebook import Summarised
from ._fit import FitFailed, identify
from ._hints import option_parameters
from ._records import IdentificationError

#: Combinations compared at most unless the caller raises it (each is a full fit).
MAX_FITS = 8


@dataclass(repr=False)
class Comparison(Summarised):
    """The fits of every combination, best first.

    Attributes
    ----------
    rows : list of dict
        Per combination: ``variants``, ``adequate``, ``reasons``, ``bic``, ``cost``,
        ``estimate``, or ``failed`` with the reason.
    results : list
        The :class:`IdentResult` of each row (None where the fit failed).
    """

    rows: list = field(default_factory=list)
    results: list = field(default_factory=list)

    def _facts(self) -> dict:
        return {"structures": len(self.rows), "adequate": sum(bool(r.get("adequate")) for r in self.rows),
                "chosen": self.rows[0]["variants"] if self.rows else None}

    @property
    def best(self):
        """The best fit (the first row's result)."""
        return self.results[0]

    def plot(self):
        """The residuals of every structure side by side (a matplotlib Figure)."""
        from ._plot import comparison_figure

        return comparison_figure(self)

    def write_report(self, folder) -> object:
        """The best fit's report folder with ``comparison.png`` added (assembled aside
        and moved in whole).

        Parameters
        ----------
        folder : str or Path
            The folder.
        """
        from ._plot import write_report

        return write_report(self.best, folder, {"comparison": self.plot()})

    def to_dict(self) -> dict:
        """Plain data (``--json``)."""
        return {"comparison": self.rows, "chosen": self.rows[0]["variants"] if self.rows else None}


def combinations(options: dict, variants: dict | None = None, max_fits: int = MAX_FITS) -> list[dict]:
    """Every combination of the option values (checked against the registry).

    Parameters
    ----------
    options : dict
        Variant or option key -> list of values.
    variants : dict, optional
        Fixed overrides the combinations are added to.
    max_fits : int
        Most combinations allowed.
    """
    from ..model.components import VARIANTS

    for key, values in options.items():
        if key not in VARIANTS:
            raise IdentificationError(f"--compare {key}: not a variant or option{nearest(key, VARIANTS)}")
        for v in values:
            if v not in VARIANTS[key]:
                raise IdentificationError(f"--compare {key}={v}: not a value of {key}{nearest(v, VARIANTS[key])}; "
                                          f"choose from {', '.join(VARIANTS[key])}")
    keys = list(options)
    combos = [{**(variants or {}), **dict(zip(keys, vals, strict=True))}
              for vals in itertools.product(*(options[k] for k in keys))]
    if len(combos) > max_fits:
        raise IdentificationError(f"--compare: {len(combos)} combinations, above --max-fits {max_fits} (each is a "
                                  "full fit); raise --max-fits to run them")
    return combos


def bic(result) -> float:
    """The Bayesian information criterion of a fit (module docstring).

    Parameters
    ----------
    result : IdentResult
        A fit.
    """
    chans = result.channels
    N = sum(c["samples"] for c in chans)
    m2ll = 0.0
    for name in {c["channel"] for c in chans}:
        rows = [c for c in chans if c["channel"] == name]
        if name in result.sigma_estimated:
            n = sum(c["samples"] for c in rows)
            rss = sum(c["rms"] ** 2 * c["samples"] for c in rows)
            m2ll += n * np.log(rss / n)
        else:
            m2ll += sum(c["chi2"] for c in rows)
    return float(m2ll + len(result.names) * np.log(N))


def compare(params, records, free, options: dict, *, sigma: dict | None = None, variants: dict | None = None,
            max_fits: int = MAX_FITS, max_evaluations: int = 60, progress: bool = False,
            estimate_x0=False, model_error: float | None = None, friction_start: str = "off",
            allow_misfit: bool = False, coarse_to_fine: bool = False) -> Comparison:
    """Fit every combination of ``options`` and rank them (module docstring).

    Parameters
    ----------
    params : Parameters
        The parameter set.
    records : sequence of str or Path
        The records.
    free : sequence of str
        The free parameters (the same for every combination; one that a combination's
        parts do not use, such as the clamping band ``w_aw`` with back-calculation, or
        a friction option's own parameter where that option is off (``r_start``,
        ``v_st`` with ``stribeck = off``), is left out of that combination's fit and
        named in its row's ``not_used``).
    options : dict
        Variant or option key -> values to compare (``{"anti_windup": ["backcalc",
        "clamping"]}``).
    sigma, variants, max_evaluations, progress, estimate_x0, model_error, friction_start, allow_misfit, coarse_to_fine
        As for :func:`~ema_casadi.identification.identify`.
    max_fits : int
        Most combinations (refused above).
    """
    from ..model.assembly import build_model

    rows, results = [], []
    free = [s.strip() for s in free.split(",") if s.strip()] if isinstance(free, str) else list(free)
    for combo in combinations(options, variants, max_fits):
        model = build_model(params, combo)
        # a parameter of a structure the combination leaves out (w_aw without clamping): not fitted there
        unused = [n for n in free if n in model.param_names and (n not in model.used_params
                                                                  or n in option_parameters(model.variants))]
        mine = [n for n in free if n not in unused]
        try:
            res = identify(params, records, mine, sigma=sigma, variants=combo, max_evaluations=max_evaluations,
                           progress=progress, estimate_x0=estimate_x0, friction_start=friction_start,
                           coarse_to_fine=coarse_to_fine,
                           allow_misfit=allow_misfit,
                           **({} if model_error is None else {"model_error": model_error}))
        except FitFailed as exc:
            rows.append({"variants": combo, "failed": exc.reason, "adequate": False, "bic": float("inf")})
            results.append(None)
            continue
        rows.append({"variants": combo, "adequate": res.adequacy["adequate"], "reasons": res.adequacy["reasons"],
                     **({"not_used": unused} if unused else {}),
                     "verdict": res.adequacy.get("verdict"), "exact": bool(res.adequacy.get("exact")),
                     "bic": bic(res), "cost": res.info["cost"], "estimate": res.estimate})
        results.append(res)
    # adequate first, then adequate within model error, then inadequate; by BIC within each
    order = sorted(range(len(rows)), key=lambda k: (not rows[k]["adequate"], not rows[k].get("exact", False),
                                                    rows[k]["bic"]))
    return Comparison([rows[k] for k in order], [results[k] for k in order])
