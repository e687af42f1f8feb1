"""The report's pieces: the verdict vocabulary and its rules, sentences formatted from values,
the layout (setup one line, readings a legend one a line, reasons as footnotes)."""

import pickle

import pytest

from fir_gym.scenarios.prose import Printed, join, literal_numbers, say
from fir_gym.scenarios.report import (
    VERDICTS,
    Report,
    agrees,
    claim,
    excluded_by,
    is_verdict,
    number_verdict,
    printed_half_unit,
    reproduced,
)


def test_printed_precision():
    assert printed_half_unit("0.0250") == pytest.approx(5e-5)
    assert printed_half_unit("44.4709") == pytest.approx(5e-5)
    assert printed_half_unit("3") == pytest.approx(0.5)
    assert printed_half_unit("-0.7251") == pytest.approx(5e-5)
    assert printed_half_unit("1e-3") == pytest.approx(5e-4)


def test_deterministic_numbers_agree_to_the_printed_digits():
    assert agrees("0.0013", 0.001274) and agrees("0.0013", 0.00134)
    assert not agrees("0.0013", 0.00136) and not agrees("0.0031", 0.002835)


def test_monte_carlo_numbers_agree_within_ten_percent_or_two_standard_errors():
    assert agrees("13.3778", 14.26, se=0.1)            # 6.6 %
    assert not agrees("13.3778", 15.0, se=0.1)         # 12 %
    assert agrees("13.3778", 15.0, se=1.0)             # within 2 s.e.


def test_a_floor_excludes_a_paper_number_whatever_our_estimate():
    assert excluded_by("3.3969", 3.914) and not excluded_by("3.3969", 3.6)
    assert number_verdict("3.3969", 3.4, se=0.1, floor=5.74) == "not reproduced: bound"
    assert number_verdict("3.3969", 3.4, se=0.1) == "reproduced"
    assert number_verdict("3.3969", 3.4, se=0.1, reading="Rstd") == (
        "reproduced under reading Rstd")
    assert number_verdict("3.3969", 30.0, otherwise="ambiguous") == "not reproduced: ambiguous"
    with pytest.raises(ValueError, match="otherwise"):
        number_verdict("1.0", 2.0, otherwise="wrong")


def test_the_vocabulary_is_closed():
    for term in ("reproduced", "not reproduced: bound", "not reproduced: ambiguous",
                 "not reproduced: differs", "claim tested: holds", "claim tested: fails",
                 "beyond the paper"):
        assert term in VERDICTS and is_verdict(term)
    assert is_verdict(reproduced("eq29·GI·Rvar")) and not is_verdict("reproduced under reading")
    assert claim(True) == "claim tested: holds" and claim(False) == "claim tested: fails"
    r = Report("999", "test")
    s = r.summary("a summary", "setup", {"x": "a reading"})
    with pytest.raises(ValueError, match="not in the vocabulary"):
        s.compare("q", None, 1.0, "x", "roughly reproduced")


def test_layout_puts_setup_readings_and_reasons_around_a_short_table():
    r = Report("999", "test")
    s = r.summary("Table 9", say("setup with {n} runs", n=3),
                  {"a": "first reading", "b": "second reading"})
    s.compare("q1", Printed("1.0"), 1.01, "a", "reproduced", "the reason")
    s.compare("q2", Printed("2.0"), 2.5, "a", "not reproduced: differs", "the reason")
    text = r.to_text(markdown=True)
    assert "Setup: setup with 3 runs" in text
    assert "Readings:\n- a = first reading\n- b = second reading\n" in text   # a legend
    assert "- [1] the reason" in text and text.count("[1]") == 3    # one footnote, two refs
    header = next(line for line in text.splitlines() if line.startswith("| quantity"))
    assert [h.strip() for h in header.strip("|").split("|")] == [
        "quantity", "paper", "ours", "reading", "verdict", "why"]


def test_literal_numbers_are_found_in_templates_not_in_values():
    assert literal_numbers(say("RMSE {v:.3g} after {k} steps", v=0.123, k=10)) == []
    assert literal_numbers(say("RMSE {v:.3g} after 10 steps", v=0.123)) == ["10"]
    assert literal_numbers("about ten times, 30 % more") == ["30"]
    # references, names and formulas are not results
    assert literal_numbers("Table 1, eq 3.2, Fig. 2, Theorem 2.1, §5, paper 000, Δ22, x3") == []
    assert literal_numbers("the term `2k (x − l0)` and Φ_F(τ, 0)") == []
    assert literal_numbers(say("{v}", v="a value with 7 in it")) == ["7"]
    assert literal_numbers(say("{v}", v=Printed("0.0250"))) == []
    assert literal_numbers(join([say("{a}", a=1), say("{b}", b=2)])) == []
    with pytest.raises(ValueError, match="separator"):
        join(["a", "b"], " 1 ")


def test_prose_survives_pickling_with_its_template():
    text = say("{n} runs", n=5)
    back = pickle.loads(pickle.dumps(text))
    assert back == "5 runs" and back.template == "{n} runs" and back.values == {"n": 5}
