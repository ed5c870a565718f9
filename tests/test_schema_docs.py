from pathlib import Path

from dfcoa_opt.core.params import describe
from dfcoa_opt.scenario.reference import schema_markdown
from dfcoa_opt.scenario.schema import ScenarioSpec

README = Path(__file__).resolve().parents[1] / "scenarios" / "README.md"


def test_scenarios_readme_is_generated_from_the_schema():
    assert README.read_text() == schema_markdown(), "run: dfcoa schema > scenarios/README.md"


def test_every_key_has_a_doc_and_numbers_have_units_or_are_dimensionless():
    for key, typ, _default, unit, doc in describe(ScenarioSpec):
        assert doc, f"{key} has no doc"
        if "number" in typ and key.split(".")[-1] in ("radius", "speed", "dt", "t_max"):
            assert unit, f"{key} lacks a unit"
