"""The discovery run's ``report.md``: what a finished loop found and how it got there,
in Markdown (the named effects and open-form terms with their intervals, the held-out
error against the noise floor, the regime maps' flags, every effect tried and why it was
not enough). :mod:`pneubayes.discovery.report` writes it into the run folder.
"""

from __future__ import annotations

from pathlib import Path

from pneubayes.discovery.disagreement import flagged_bins
from pneubayes.discovery.result import DiscoveryResult
from pneubayes.inference.fit import MISFIT_RATIO


def _md(text) -> str:
    """Text safe inside a Markdown table cell."""
    return str(text).replace("|", "\\|")


def _fmt(v, spec=".4g"):
    return "-" if v is None else format(v, spec)


#: ledger actions that try a list of groups, and why the loop tried them
_GROUP_ACTIONS = {
    "last resort": "tried (the gap stayed large)",
    "catalogue sweep": "tried (near the noise floor nothing, or too little, passed)",
    "more supported": "tried (the round's first supported effects all failed)",
    "revisit": "tried again (significant in an earlier round, not added; nothing else "
               "passed)",
    "pairs": "fitted jointly (no single effect passed)",
    "other forms": "refitted (nothing passed; the named effects' other forms)",
}


def _trial_row(e: dict, action: str, what: str) -> str:
    """A ledger row of a verified trial (a single effect, a pair or another form): its
    fitted values, held-out RMSE before and after, and the test's outcome."""
    fitted = ", ".join(f"{k}={v:.4g}" for k, v in e["fitted"].items())
    return (f"| {e['step']} | {action} | {what} | {fitted} | "
            f"{e['heldout_rmse_before_Pa']:.0f} -> {e['heldout_rmse_after_Pa']:.0f} | "
            f"{e['score_gain']:.1f} ({e['windows_improved']}/{e['windows']}, "
            f"p = {e['score_p_value']:.2g}) |")


def tried_effects(ledger) -> list[tuple[str, str]]:
    """Each catalogue effect the loop verified, with why it was named or not: its last
    verdict in the ledger (``pass`` / ``reject`` entries) and whether it was added, and
    whether a later round's search left it out because the simulator cannot step it
    beside the model then (the ``search`` entries' ``not_steppable``; such an effect
    never verified is listed after the others).

    Returns
    -------
    list of (str, str)
        ``(effect, reason)`` in the order the effects were first tried, the left-out
        ones after them.
    """
    last: dict[str, dict] = {}
    added = {e["effect"] for e in ledger if e.get("action") == "add"}
    removed = {e["effect"] for e in ledger if e.get("action") == "remove"}
    for e in ledger:
        if e.get("action") in ("pass", "reject") and "effect" in e:
            last[e["effect"]] = e
    out = []
    for g, e in last.items():
        moves = (f"held-out {e['heldout_rmse_before_Pa']:.0f} -> "
                 f"{e['heldout_rmse_after_Pa']:.0f} Pa, better in "
                 f"{e['windows_improved']}/{e['windows']} windows (p = "
                 f"{e['score_p_value']:.2g})")
        if g in added and g not in removed:
            why = f"named: {moves}"
        elif g in removed:
            why = f"named, then removed (the model did as well without it); {moves}"
        elif e["action"] == "pass":
            why = f"passed ({moves}) but another effect gained more and went in first"
        elif e.get("not_better_than_control"):
            why = (f"its gain was its basin's: the current model refitted from the trial's "
                   f"point predicted {e['control_heldout_rmse_Pa']:.0f} Pa; {moves}")
        elif e.get("gain_under_floor"):
            why = f"too small a gain (under {e['min_gain_Pa']:.0f} Pa): {moves}"
        elif e.get("short_of_gap"):
            why = f"closed only {100 * (e['gap_closed'] or 0.0):.0f} % of the gap: {moves}"
        else:
            why = f"not better on held-out data: {moves}"
        out.append((g, why))
    apart: dict[str, int] = {}
    for e in ledger:
        if e.get("action") == "search":
            for g in e.get("not_steppable", ()):
                apart.setdefault(g, e.get("round"))
    note = {g: (f"not searched from round {r} on: the simulator cannot step it beside "
                "the model") for g, r in apart.items()}
    out = [(g, f"{why}; {note[g]}" if g in note else why) for g, why in out]
    return out + [(g, why) for g, why in note.items() if g not in last]


def _terms_table(title: str, terms: list, formula: str = "formula") -> list[str]:
    """A table of found open-form terms: each parameter's unit, estimate and interval
    (``formula``: the formula column's heading)."""
    lines = ["", title, "", f"| term | {formula} | parameter | unit | estimate | "
             "90 % interval |", "|---|---|---|---|---|---|"]
    for t in terms:
        for n, p in t["parameters"].items():
            est = p.get("median", p.get("estimate"))
            iv = f"[{p['q05']:.4g}, {p['q95']:.4g}]" if "q05" in p else "-"
            lines.append(f"| {_md(t['term'])} | {_md(t['formula'])} | {n} | "
                         f"{_md(p['unit'])} | {est:.4g} | {iv} |")
    return lines


#: The open-form terms' sections of discovery.json and the report, in the report's
#: order: ``(key, title, formula column's heading, (figure's alt text, caption) or None)``
#: (the figure is the one drawn under the same key).
FOUND_TERM_SECTIONS = (
    ("found_terms",
     "Open-form terms found (an extra mass flow into the chamber, kg/s, in no catalogue "
     "form; each term's parameters with their units):",
     "formula (kg/s into the chamber)",
     ("found terms", "Each term against its main variable (red), beside the mass flow "
      "the final model misses without it on the training recordings (grey: binned means "
      "and standard errors):")),
    ("found_reading_terms",
     "Open-form terms at the reading found (relaxations, plays: they change what the "
     "sensor reports, not the chamber; in no catalogue form):",
     "formula",
     ("found relaxations", "Each relaxation against its variable p - p_bar (red), beside "
      "the reading the final model misses without it on the training windows (grey: "
      "binned means and standard errors):")),
    ("found_volume_terms",
     "Open-form terms on the chamber's volume found (a hinge: the chamber holds more gas "
     "above a pressure than its fixed volume; a wall: its give is held by friction, a "
     "loop over the pressure; in no catalogue form):",
     "formula",
     ("found volume terms", "The volume each adds along the final model's pressure on "
      "the training recordings (a hinge's curve, a wall's loop):")),
    ("found_command_terms",
     "An open-form term on the command found (the valve takes it through a driver on its "
     "own clock; in no catalogue form):",
     "formula", None),
    ("found_port_terms",
     "An open-form term at the chamber's port found (a restriction in series with the "
     "valve: a fitting, a flow control's needle; in no catalogue form):",
     "formula", None),
)


def _captioned(figs: dict, key: str, alt: str, caption: str) -> list[str]:
    """A drawn figure's lines under its caption (none where ``figs`` lacks ``key``)."""
    return ["", caption, "", f"![{alt}](figures/{figs[key]})"] if key in figs else []


def report_markdown(doc: dict, result: DiscoveryResult, figs: dict) -> str:
    """``report.md``'s text for discovery.json's ``doc`` of ``result``, with the figures'
    file names ``figs`` (by kind; those not drawn are left out)."""
    horizon = result.settings.fit.horizon_s
    noise = doc["noise_floor_Pa"]
    base, final = doc["rmse_base_Pa"], doc["rmse_final_Pa"]
    gap0, gap1 = max(base - noise, 0.0), max(final - noise, 0.0)
    lines = ["# What the model misses: discovery report", ""]
    k = result.settings.data.holdout_recordings
    how = (f"the last {k} held out whole to verify, the others to fit and search" if k else
           f"each split in time: the first {1 - result.settings.data.holdout_fraction:.0%} to fit "
           "and search, the rest to verify")
    lines += [f"Recordings: {len(doc['recordings'])} ({how}). Noise floor (sensor) "
              f"{noise:.0f} Pa; working range {doc['range_Pa'] / 1e3:.0f} kPa."
              + (" The pressure's isolated one-sample spikes were replaced by their "
                 "neighbours' mean before fitting and scoring (`fit.despike_pressure`): "
                 "every error below is against the despiked recordings."
                 if result.settings.fit.despike_pressure else ""), ""]
    lines += ["## Result", ""]
    stop = next((e for e in doc["ledger"] if e["action"] == "time budget"), None)
    if stop is not None:
        lines += [f"The loop stopped at its time budget ({stop['max_seconds']:g} s, "
                  f"`rounds.max_seconds`), {stop['where']}: what follows is the model it "
                  "had then, not where its search would have ended.", ""]
    if doc["effects"]:
        lines += ["| effect | parameter | estimate | 90 % interval | inclusion | "
                  "held-out RMSE before -> after (Pa) | log predictive gain (p of the RMSE drop) |",
                  "|---|---|---|---|---|---|---|"]
        for e in doc["effects"]:
            for n, p in e["parameters"].items():
                est = p.get("median", p.get("estimate"))
                iv = f"[{p['q05']:.4g}, {p['q95']:.4g}]" if "q05" in p else "-"
                ev = e["evidence"]
                lines.append(f"| {e['name']} | {n} | {est:.4g} | {iv} | "
                             # (None: a stage, not the library's search, proposed it)
                             f"{_fmt(ev['inclusion_probability'], '.2f')} | "
                             f"{e['rmse_before_Pa']:.0f} -> {e['rmse_after_Pa']:.0f} | "
                             f"{ev['score_gain']:.1f} ({ev['score_p_value']:.2g}) |")
    for key, title, formula, figure in FOUND_TERM_SECTIONS:
        if doc.get(key):
            lines += _terms_table(title, doc[key], formula=formula)
            if figure is not None:
                lines += _captioned(figs, key, *figure)
    if doc.get("stand_ins"):
        lines += ["", "Kept as stand-ins, not named: catalogue effects that improve the "
                  "prediction only with a parameter of their own at a bound, a strained "
                  "form standing in for something it cannot express:", ""]
        for e in doc["stand_ins"]:
            where = "; ".join(f"{b['parameter']} at its {b['bound']} bound {b['value']:.4g}"
                              for b in e["at_bounds"])
            lines.append(f"- {e['name']} ({where}): held-out RMSE {e['rmse_before_Pa']:.0f} "
                         f"-> {e['rmse_after_Pa']:.0f} Pa")
    if doc["effects"] or doc.get("stand_ins") \
            or any(doc.get(key) for key, *_ in FOUND_TERM_SECTIONS):
        found = True
    elif final <= MISFIT_RATIO * noise:
        found = False
        lines.append(f"No missing effect is supported, and the plain thin-port model's "
                     f"held-out error ({final:.0f} Pa) is within {MISFIT_RATIO:g} x the "
                     f"noise floor ({noise:.0f} Pa).")
    else:
        found = False
        lines.append(f"No candidate effect is supported, but the model still misses: its "
                     f"held-out error ({final:.0f} Pa) is {final / noise:.1f} x the noise "
                     f"floor ({noise:.0f} Pa). What is missing is not among the "
                     "catalogue's candidates, no open-form term passed verification, or "
                     "the data cannot show it.")
    if found and final > MISFIT_RATIO * noise:
        lines.append(f"\nThe final model still misses by {final / noise:.1f} x the noise "
                     "floor: the named effects do not explain everything.")
    spiky = sorted({f["recording"] for f in doc.get("input_findings", ())
                    if f["rule"] == "pressure-spikes"})
    if spiky and final > MISFIT_RATIO * noise and not result.settings.fit.despike_pressure:
        lines.append(f"\nThe input check found isolated one-sample spikes in {len(spiky)} "
                     "recording(s) (rule `pressure-spikes`; the noise floor is estimated "
                     "past them): no model follows a glitch, and each weighs in the "
                     "held-out error. " + "; ".join(_md(Path(r).name) for r in spiky[:5])
                     + ("; ..." if len(spiky) > 5 else ""))
    shrink = "" if gap0 <= 0 else f" ({100 * (1 - gap1 / gap0):.0f} % of the gap closed)"
    span = doc.get("span_Pa")
    of_span = "" if not span else f" ({100 * final / span:.2f} % of the measured span)"
    lines += ["", f"Held-out {horizon:g}-s prediction RMSE: base {base:.0f} Pa -> final "
              f"{final:.0f} Pa{of_span}; gap above the noise floor {gap0:.0f} -> "
              f"{gap1:.0f} Pa{shrink}.", ""]
    lines += ["## Where the base model disagrees", ""]
    # no map without a search round (max_effects 0: the base model and its posterior)
    flags = flagged_bins(result.maps[0], "prediction") if result.maps else None
    if flags is None:
        lines.append("Not mapped: the loop ran no search round (max_effects 0).")
    elif flags:
        lines += ["| regime | bin | samples | RMS (Pa) | excess over noise (Pa) | bias z |",
                  "|---|---|---|---|---|---|"]
        for fam, b in flags[:12]:
            lines.append(f"| {fam} | {_md(b['bin'])} | {b['n']} | {b['rms']:.0f} | "
                         f"{b['excess_rms']:.0f} | {b['z_bias']:.1f} |")
    else:
        lines.append("No regime bin is flagged.")
    if "disagreement" in figs:
        lines += ["", f"![disagreement](figures/{figs['disagreement']})"]
    lines += ["", "## Evidence (grouped SINDy on the one-step residual, block-bagged)", ""]
    for s in result.searches:
        lines += [f"Round {s['round']} (model: thin port"
                  + "".join(f" + {m}" for m in s["model"]) + ")", "",
                  "| effect | inclusion probability | best term | t | explained |",
                  "|---|---|---|---|---|"]
        for g in s["ranking"]:
            e = s["evidence"][g]
            lines.append(f"| {g} | {e['inclusion_probability']:.2f} | {_md(e['best_term'])} | "
                         f"{e['t_max']:.1f} | {100 * e['explained_fraction']:.2f} % |")
        lines.append("")
    if "evidence" in figs:
        lines += [f"![evidence](figures/{figs['evidence']})", ""]
    tried = tried_effects(doc["ledger"])
    if tried:
        lines += ["## Catalogue effects tried", "", "| effect | outcome |", "|---|---|"]
        lines += [f"| {g} | {_md(why)} |" for g, why in tried]
        lines.append("")
    lines += ["## Ledger", "", "| step | action | effect | fitted | held-out RMSE (Pa) | "
              "log predictive gain (windows better, p) |", "|---|---|---|---|---|---|"]
    for e in doc["ledger"]:
        if e["action"] == "remove":
            lines.append(f"| {e['step']} | remove | {e['effect']} | | "
                         f"{e['heldout_rmse_before_Pa']:.0f} -> {e['heldout_rmse_after_Pa']:.0f}"
                         f" | p = {e['score_p_value']:.2g} |")
        elif e["action"] == "add":
            lines.append(f"| {e['step']} | add | {e['effect']}"
                         + (f" (pair with {[g for g in e['pair'] if g != e['effect']][0]})"
                            if "pair" in e else "") + " | | "
                         f"{e['heldout_rmse_before_Pa']:.0f} -> {e['heldout_rmse_after_Pa']:.0f}"
                         f" | {e['score_gain']:.1f} (p = {e['score_p_value']:.2g}) |")
        elif e["action"] in ("pass", "reject"):
            lines.append(_trial_row(e, e["action"], e["effect"]))
        elif e["action"] == "pair":
            lines.append(_trial_row(e, f"pair {'pass' if e['passed'] else 'reject'}",
                                    " + ".join(e["effects"])))
        elif e["action"] == "form":
            lines.append(_trial_row(e, f"form {'pass' if e['passed'] else 'reject'}",
                                    f"{e['effect']} {e['from']} -> {e['to']}"))
        elif e["action"] == "swap form":
            lines.append(f"| {e['step']} | swap form | {e['effect']} as {e['to']} | | "
                         f"{e['heldout_rmse_before_Pa']:.0f} -> {e['heldout_rmse_after_Pa']:.0f}"
                         " | |")
        elif e["action"] in ("open form pass", "open form reject"):
            fitted = ", ".join(f"{t['term']}: " + ", ".join(
                f"{k}={v:.4g}" for k, v in t.items() if k != "term") for t in e["terms"])
            lines.append(f"| {e['step']} | {e['action']} | closure | {_md(fitted)} | "
                         f"{e['heldout_rmse_before_Pa']:.0f} -> {e['heldout_rmse_after_Pa']:.0f}"
                         f" | {e['score_gain']:.1f} ({e['windows_improved']}/{e['windows']}, "
                         f"p = {e['score_p_value']:.2g}) |")
        elif e["action"] in ("reading form pass", "reading form reject",
                             "volume form pass", "volume form reject"):
            fitted = "; ".join(", ".join(f"{k}={v:.4g}" for k, v in t.items())
                               for t in e["fitted_terms"])
            lines.append(f"| {e['step']} | {e['action']} | {e['effect']} | {_md(fitted)} | "
                         f"{e['heldout_rmse_before_Pa']:.0f} -> {e['heldout_rmse_after_Pa']:.0f}"
                         f" | {e['score_gain']:.1f} ({e['windows_improved']}/{e['windows']}, "
                         f"p = {e['score_p_value']:.2g}) |")
        elif e["action"] == "open form search":
            lines.append(f"| {e['step']} | open form search | "
                         + (", ".join(_md(t["term"]) for t in e["terms"]) or "no term")
                         + " proposed | | | |")
        elif e["action"] == "open form prune":
            lines.append(f"| {e['step']} | open form prune | {_md(e['term'])} | | "
                         f"{e['heldout_rmse_before_Pa']:.0f} -> {e['heldout_rmse_after_Pa']:.0f}"
                         " | |")
        elif e["action"] == "time budget":
            lines.append(f"| {e['step']} | time budget | spent {_md(e['where'])} "
                         f"({e['max_seconds']:g} s) | | | |")
        elif e["action"] == "search":
            lines.append(f"| {e['step']} | search | {', '.join(e['supported']) or 'none'} "
                         "supported | | | |")
        elif e["action"] in _GROUP_ACTIONS:
            lines.append(f"| {e['step']} | {e['action']} | {', '.join(e['groups'])} "
                         f"{_GROUP_ACTIONS[e['action']]} | | | |")
        else:
            lines.append(f"| {e['step']} | {e['action']} | | | "
                         f"{_fmt(e.get('heldout_rmse_Pa'), '.0f')} | |")
    if "disagreement_final" in figs:
        lines += ["", "## Final model", "", f"![final](figures/{figs['disagreement_final']})"]
    if result.posterior_info is not None and result.settings.posterior.method == "laplace":
        info = result.posterior_info
        check = info.get("importance_check")
        bounded = info.get("mode_on_prior_bound") or []
        lines += ["", f"Posterior: Laplace approximation at the posterior's mode, "
                  f"{result.settings.posterior.laplace_draws} draws (a Gaussian: no skew, one mode)"
                  + (f"; the mode on the prior bound of {', '.join(bounded)}: the "
                     "Gaussian fitted inside, cut at the bound" if bounded else "")
                  + ("" if check is None else
                     f"; importance check on {check['draws']} draws: Pareto k "
                     f"{_fmt(check['pareto_k'], '.2f')} (reliable <= "
                     f"{check['khat_threshold']:.2f})")
                  + f". Reliable: {info['converged']}."
                  + ("" if info["converged"] else
                     " **Not concave at the mode, or the posterior has mass the Gaussian "
                     "misses: its intervals are not the posterior's; sample it with "
                     "emcee.**")]
    elif result.posterior_info is not None:
        sm = result.settings.fit.sampler
        chains = (f"{sm.rhat_groups} walker groups" if sm.rhat_groups else "walkers")
        lines += ["", f"Posterior: emcee, {result.posterior_info['steps']} steps, "
                  f"converged {result.posterior_info['converged']} (R-hat <= "
                  f"{sm.max_rhat} over {chains} as chains, bulk "
                  f"and tail ESS >= {sm.target_ess:g}, {sm.tau_factor:g} autocorrelation "
                  "times)."]
    lines += ["", f"Seed {doc['seed']}; pneubayes {doc['pneubayes_version']}; wall time "
              f"{_fmt(doc['wall_time_s'], '.0f')} s.", ""]
    return "\n".join(lines)
