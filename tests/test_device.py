"""grisx.device: the register budgets' environment override (used by register sweeps on a GPU)."""

from __future__ import annotations

import pytest

from grisx.device import register_budget
from grisx.errors import InvalidValueError


def test_register_budget_default_and_override(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("GRISX_TEST_REGISTERS", raising=False)
    assert register_budget("GRISX_TEST_REGISTERS", 80) == 80
    monkeypatch.setenv("GRISX_TEST_REGISTERS", " 96 ")
    assert register_budget("GRISX_TEST_REGISTERS", 80) == 96


@pytest.mark.parametrize("text", ["0", "31", "256", "ninety", "96.5"])
def test_register_budget_outside_cudas_range_names_the_variable(monkeypatch: pytest.MonkeyPatch, text: str) -> None:
    monkeypatch.setenv("GRISX_TEST_REGISTERS", text)
    with pytest.raises(InvalidValueError, match="GRISX_TEST_REGISTERS"):
        register_budget("GRISX_TEST_REGISTERS", 80)
