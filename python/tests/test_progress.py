"""Progress of long fits: the callback is called from the running fit, with the GIL, per
iteration and per stage; its exception stops the fit."""

import time

import pytest

import bouncefit

COPPER = "datasets/copper-flash"
ALUMINIUM = "datasets/aluminium-pinhole"


def monotone_per_stage(events):
    """Each stage's `done` never decreases, stays within its `total`, and reaches it."""
    last = {}
    for stage, done, total, _ in events:
        assert 0 <= done <= total, (stage, done, total)
        assert done >= last.get(stage, 0), (stage, done, last[stage])
        last[stage] = done
    return last


def test_a_uniform_fit_reports_each_iteration():
    events = []
    fit = bouncefit.fit(ALUMINIUM, ["single", "kulla-conty"], fresnel="conductor",
                        progress=lambda *e: events.append(e))
    last = monotone_per_stage(events)
    assert {"fit single", "fit kulla-conty", "fitted"} <= set(last)
    # One report per point of the chosen fit's optimiser trace, then "done".
    iterations = [e for e in events if e[0] == f"fit {fit.model}" and e[3] != "done"]
    assert [e[1] for e in iterations] == [p["iteration"] for p in fit.data["trace"]]
    assert len(iterations) > 3
    assert all(e[3].startswith("loss ") for e in iterations)
    assert [e[1:3] for e in events if e[0] == "fitted"] == [(1, 2), (2, 2)]


def test_a_maps_fit_reports_its_stages_and_texels():
    events = []
    bouncefit.fit("datasets/two-materials", "kulla-conty", maps=True, texels="16x16", bases=2,
                  coarse_to_fine=8, progress=lambda *e: events.append(e))
    last = monotone_per_stage(events)
    assert "maps fit" in last and "maps 16x16" in last
    assert [e for e in events if e[0] == "maps 16x16"][-1][1:3] == (256, 256)


class Stop(Exception):
    pass


@pytest.mark.parametrize("maps", [False, True])
def test_an_exception_in_the_callback_stops_the_fit(maps):
    calls = []

    def progress(stage, done, total, message):
        calls.append(stage)
        if len(calls) == 3:
            raise Stop("enough")

    options = dict(maps=True, texels="32x32", coarse_to_fine=8) if maps else {}
    started = time.perf_counter()
    with pytest.raises(Stop, match="enough"):
        bouncefit.fit("datasets/two-materials", "kulla-conty", progress=progress, **options)
    assert len(calls) == 3  # not called again once it raised
    assert time.perf_counter() - started < 20


def test_an_exception_in_the_callback_stops_the_sampler(tmp_path):
    mcmc = []

    def progress(stage, done, total, message):
        if stage == "mcmc":
            mcmc.append((done, total))
            if len(mcmc) == 5:
                raise Stop("enough sampling")

    started = time.perf_counter()
    with pytest.raises(Stop, match="enough sampling"):
        bouncefit.fit(COPPER, mcmc=True, output=tmp_path / "fit.json", progress=progress)
    assert len(mcmc) == 5 and mcmc[-1][0] < mcmc[-1][1]  # stopped well before its end
    assert time.perf_counter() - started < 30
    assert not (tmp_path / "fit.json").exists()  # no partial output


def test_tqdm_bars():
    pytest.importorskip("tqdm")
    fit = bouncefit.fit(COPPER, progress="tqdm")
    assert fit.model == "single"
    with pytest.raises(bouncefit.InvalidInputError, match="progress"):
        bouncefit.fit(COPPER, progress="bar")
