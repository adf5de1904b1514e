"""One vocabulary of render params: every registered method, every param (issue: consistent params)."""

from __future__ import annotations

from collections import defaultdict

from grisx.render.driver import METHODS
from grisx.render.base.registry import SYNONYMS, VOCABULARY


def test_every_param_has_help_and_no_synonym():
    for name, method in METHODS.items():
        for p in method.params:
            assert p.name not in SYNONYMS, f"{name}: '{p.name}' is a synonym of '{SYNONYMS[p.name]}'"
            assert len(p.doc.strip()) >= 10, f"{name}: param '{p.name}' has no help text"


def test_shared_names_mean_one_thing():
    kinds = defaultdict(set)
    for name, method in METHODS.items():
        for p in method.params:
            kinds[p.name].add(p.kind)
    for pname, ks in kinds.items():
        assert len(ks) == 1, f"param '{pname}' has different types across methods: {ks}"
        if pname in VOCABULARY:
            assert ks == {VOCABULARY[pname][0]}, pname
    shared = {n for n, ms in ((n, [m for m in METHODS.values() if any(p.name == n for p in m.params)]) for n in kinds) if len(ms) > 1}
    assert shared <= set(VOCABULARY), f"params shared by several methods but not in the vocabulary: {sorted(shared - set(VOCABULARY))}"


def test_every_path_renderer_takes_the_depth_convention():
    for name in ("pt", "restir-gi", "restir-pt"):
        names = {p.name for p in METHODS[name].params}
        assert {"max_depth", "rr_depth"} <= names, name
    for name in ("restir-di", "restir-gi", "restir-pt"):
        assert "jitter" in {p.name for p in METHODS[name].params}, name
