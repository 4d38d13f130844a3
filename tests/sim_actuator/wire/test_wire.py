"""The controllers' wire formats both ends share: the MTS-like lines and the state codes."""

from __future__ import annotations

import pytest

from sim_actuator.wire.mts_lines import MalformedReply, Refused, err, ok, parse_reply, split_request
from sim_actuator.wire.states import ControllerState, FaultCode, fault_name, state_name


def test_an_ok_reply_parses_back_exactly() -> None:
    line = ok(ramp=3, time=0.1 + 0.2, displacement=-1.25e-7, force=35.4, command=2.5)
    assert line == "OK ramp=3 time=0.30000000000000004 displacement=-1.25e-07 force=35.4 " \
        "command=2.5"
    fields = parse_reply(line)
    assert float(fields["time"]) == 0.1 + 0.2 and int(fields["ramp"]) == 3
    assert parse_reply("OK") == {}


def test_err_and_malformed_replies_are_told_apart() -> None:
    with pytest.raises(Refused) as refused:
        parse_reply(err("BAD_VALUE", "ramp time must be within [0, 60] s"))
    assert refused.value.code == "BAD_VALUE" and "within [0, 60]" in refused.value.message
    for bad in ("HELLO", "OK ramp", ""):
        with pytest.raises(MalformedReply):
            parse_reply(bad)


def test_requests_split_into_a_case_insensitive_verb_and_arguments() -> None:
    assert split_request("  run 1.5   10 ") == ("RUN", ["1.5", "10"])
    assert split_request("") == ("", [])


def test_state_and_fault_codes_have_one_numbering() -> None:
    assert [int(s) for s in ControllerState] == [0, 1, 2, 3, 4]
    assert state_name(4) == "INTERLOCK" and state_name(9) == "UNKNOWN(9)"
    assert fault_name(int(FaultCode.FORCE_LIMIT)) == "FORCE_LIMIT" and fault_name(7) == "UNKNOWN(7)"
