"""crossway.stopping: real signals sent to this process, one raised inside a finalizer, where
Python swallows what the handler raises."""

import signal
import sys

import pytest

from crossway.stopping import StopRequest, stop_handlers


class SignalsWhenCollected:
    def __init__(self, signum: int) -> None:
        self.signum = signum

    def __del__(self):
        signal.raise_signal(self.signum)  # the handler runs here, inside the finalizer


@pytest.mark.parametrize("signum, sigterm_exits, raised", [
    (signal.SIGINT, False, KeyboardInterrupt), (signal.SIGTERM, False, KeyboardInterrupt),
    (signal.SIGINT, True, KeyboardInterrupt), (signal.SIGTERM, True, SystemExit)])
def test_a_signal_swallowed_by_a_finalizer_is_raised_again_by_check(monkeypatch, signum, sigterm_exits, raised):
    swallowed = []
    monkeypatch.setattr(sys, "unraisablehook", lambda hook_args: swallowed.append(hook_args.exc_type))
    with stop_handlers(StopRequest(sigterm_exits=sigterm_exits)) as stop:
        stop.check()  # no signal yet: nothing
        SignalsWhenCollected(signum)  # collected at once
        assert swallowed == [raised] and stop.signal == signum
        with pytest.raises(raised) as caught:
            stop.check()
    if raised is SystemExit:
        assert caught.value.code == 128 + signal.SIGTERM  # a process killed by SIGTERM says 143


def test_a_signal_outside_a_finalizer_raises_at_once():
    with stop_handlers(StopRequest()) as stop:
        with pytest.raises(KeyboardInterrupt):
            signal.raise_signal(signal.SIGTERM)
        assert stop.signal == signal.SIGTERM


def test_handlers_come_back_and_an_ignored_ctrl_c_stays_ignored():
    before_term, before_int = signal.getsignal(signal.SIGTERM), signal.getsignal(signal.SIGINT)
    with stop_handlers(StopRequest()) as stop:
        assert signal.getsignal(signal.SIGTERM) is stop and signal.getsignal(signal.SIGINT) is stop
    assert signal.getsignal(signal.SIGTERM) is before_term and signal.getsignal(signal.SIGINT) is before_int
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)  # as in a command a shell started in the background
    try:
        with stop_handlers(StopRequest()) as stop:
            assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN and signal.getsignal(signal.SIGTERM) is stop
        assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGINT, previous)
