"""``pneubayes discover``: run the loop and write the run folder.

``RUNDIR/discovery.json`` (format ``pneubayes-discovery/1``), ``RUNDIR/model.json`` (the
final model card: posterior median, or the refined point without a posterior),
``RUNDIR/posterior.nc`` with ``RUNDIR/chain.h5`` (the final model's emcee posterior, so
``pneubayes predict RUNDIR`` works; a rerun whose final model differs keeps the older
chain as ``chain.<fingerprint>.h5``), ``RUNDIR/disagreement.json`` (the regime maps of
every round), ``RUNDIR/report.md`` and ``RUNDIR/figures/``. Files are written
atomically.
"""

from __future__ import annotations

from pathlib import Path

from pneubayes.atomic import write_json_atomic, write_text_atomic
from pneubayes.discovery.loop import Discovery
from pneubayes.discovery.report_text import report_markdown
from pneubayes.discovery.result import DiscoveryResult
from pneubayes.discovery.settings import DiscoverySettings
from pneubayes.inference.fit_folder import write_posterior
from pneubayes.io.plausibility import recorded_findings


def run_discover(recordings, settings: DiscoverySettings, out_dir, log=print,
                 figures: bool = True) -> dict:
    """Run :class:`Discovery` on ``recordings``; write ``out_dir``; return discovery.json."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    recs = list(recordings)
    result = Discovery(settings, out, log).fit(recs).result_
    return write_discovery(result, recs, out, figures)


def write_discovery(result: DiscoveryResult, recordings, out_dir,
                    figures: bool = True) -> dict:
    """Write a :class:`DiscoveryResult` as a run folder; return discovery.json's doc.

    Parameters
    ----------
    result : DiscoveryResult
        A finished discovery (``Discovery(...).fit(recordings).result_``).
    recordings : sequence of Recording
        The recordings it ran on (their sources are listed in the document).
    out_dir : path
        The run folder: ``discovery.json``, ``model.json``, ``disagreement.json``,
        ``report.md``, ``posterior.nc`` (with a posterior), ``found_effect.py`` (with
        open-form terms) and ``figures/``.
    figures : bool
        Draw the figures (matplotlib).

    Returns
    -------
    dict
        The ``discovery.json`` document.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    recs = list(recordings)
    doc = result.to_dict()
    doc["recordings"] = [str(r.source) for r in recs]
    doc["input_findings"] = recorded_findings(recs)
    result.model.save_card(result.params, out / "model.json",
                           extra={"fit": {"estimate": result.estimate,
                                          "by": "pneubayes discover",
                                          **result.settings.fit.preparation()}})
    if result.posterior is not None:  # beside the card, as pneubayes fit writes it
        write_posterior(result.posterior, out / "posterior.nc")
        doc["posterior"]["file"] = "posterior.nc"
    write_json_atomic(out / "disagreement.json", {"rounds": list(result.maps)})
    if doc.get("found_terms"):  # the found terms as an effect plug-in to name and edit
        from pneubayes.discovery.openform.skeleton import effect_skeleton

        write_text_atomic(out / "found_effect.py", effect_skeleton(result.model, result.params))
        doc["found_effect"] = "found_effect.py"
    if doc.get("found_volume_terms"):  # the volume's hinges or walls as another
        from pneubayes.discovery.openform.skeleton import volume_effect_skeleton

        write_text_atomic(out / "found_volume.py",
                          volume_effect_skeleton(result.model, result.params))
        doc["found_volume_effect"] = "found_volume.py"
    if doc.get("found_port_terms"):  # the port's restriction as another
        from pneubayes.discovery.openform.skeleton import port_effect_skeleton

        write_text_atomic(out / "found_port.py",
                          port_effect_skeleton(result.model, result.params))
        doc["found_port_effect"] = "found_port.py"
    if result.model.has("reading_closure"):  # and the reading's relaxations as another
        from pneubayes.discovery.openform.skeleton import reading_effect_skeleton

        write_text_atomic(out / "found_reading.py",
                          reading_effect_skeleton(result.model, result.params))
        doc["found_reading_effect"] = "found_reading.py"
    if result.model.has("reading_play"):  # and its plays as another
        from pneubayes.discovery.openform.skeleton import play_effect_skeleton

        write_text_atomic(out / "found_reading_play.py",
                          play_effect_skeleton(result.model, result.params))
        doc["found_reading_play_effect"] = "found_reading_play.py"
    if result.model.has("reading_command"):  # and its lags of the command as another
        from pneubayes.discovery.openform.skeleton import command_effect_skeleton

        write_text_atomic(out / "found_reading_command.py",
                          command_effect_skeleton(result.model, result.params))
        doc["found_reading_command_effect"] = "found_reading_command.py"
    if result.model.has("reading_hinge"):  # and its knees as another
        from pneubayes.discovery.openform.skeleton import hinge_effect_skeleton

        write_text_atomic(out / "found_reading_hinge.py",
                          hinge_effect_skeleton(result.model, result.params))
        doc["found_reading_hinge_effect"] = "found_reading_hinge.py"
    if result.model.has("reading_flow"):  # and its terms of the port flows as another
        from pneubayes.discovery.openform.skeleton import flow_effect_skeleton

        write_text_atomic(out / "found_reading_flow.py",
                          flow_effect_skeleton(result.model, result.params))
        doc["found_reading_flow_effect"] = "found_reading_flow.py"
    write_json_atomic(out / "discovery.json", doc)
    figs = {}
    if figures and result.maps:  # (no search round, no map: max_effects 0)
        from pneubayes.plotting import plot_disagreement, plot_evidence

        figs["disagreement"] = plot_disagreement(
            result.maps[0], out / "figures" / "disagreement.png",
            "base model: residual RMS by regime (red: flagged; dashed: noise)").name
        if len(result.maps) > 1:
            figs["disagreement_final"] = plot_disagreement(
                result.maps[-1], out / "figures" / "disagreement_final.png",
                "final model: residual RMS by regime").name
        figs["evidence"] = plot_evidence(result.searches, out / "figures" / "evidence.png").name
    if figures and doc.get("found_terms"):
        from pneubayes.discovery.openform.term_view import term_views
        from pneubayes.plotting import plot_found_terms

        views = term_views(result.model, result.params, result.train, result.settings.search.block,
                           result.settings.search.solver)
        figs["found_terms"] = plot_found_terms(views,
                                               out / "figures" / "found_terms.png").name
    if figures and any(result.model.has(c) for c in ("reading_closure", "reading_flow",
                                                      "reading_hinge")):
        from pneubayes.discovery.openform.flow_view import flow_views
        from pneubayes.discovery.openform.hinge_view import hinge_views
        from pneubayes.discovery.openform.reading_view import reading_views
        from pneubayes.plotting import plot_found_reading_terms

        views = [v for has, fn in (("reading_closure", reading_views),
                                   ("reading_flow", flow_views),
                                   ("reading_hinge", hinge_views))
                 if result.model.has(has)
                 for v in fn(result.model, result.params, result.train,
                             result.settings.fit.horizon_s, result.settings.fit.refine_solver)]
        figs["found_reading_terms"] = plot_found_reading_terms(
            views, out / "figures" / "found_reading_terms.png").name
    if figures and doc.get("found_volume_terms"):
        from pneubayes.discovery.openform.volume_view import volume_views
        from pneubayes.plotting import plot_found_volume_terms

        views = volume_views(result.model, result.params, result.train,
                             result.settings.fit.refine_solver)
        figs["found_volume_terms"] = plot_found_volume_terms(
            views, out / "figures" / "found_volume_terms.png").name
    write_text_atomic(out / "report.md", report_markdown(doc, result, figs))
    return doc


__all__ = ["run_discover"]
