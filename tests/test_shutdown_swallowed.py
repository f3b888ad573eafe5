"""A stopping signal whose exception is swallowed (weakref callback) still stops the command."""

import signal
import weakref

import pytest

from vehid.scenarios.shutdown import Interrupted, stopping_on_signals


class _Thing:
    pass


@pytest.fixture
def ctrl_c_as_at_a_terminal():
    """SIGINT handled by Python's KeyboardInterrupt handler, as a command started at a terminal has it.

    A job started in the background of a non-interactive shell inherits SIGINT
    ignored, and the block then rightly leaves Ctrl-C alone: without this the
    SIGINT case would depend on how the test run was started.
    """
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, previous)


@pytest.mark.parametrize("stop", ["SIGTERM", "SIGINT"])
def test_a_signal_handled_inside_a_weakref_callback_still_interrupts(stop, capsys, ctrl_c_as_at_a_terminal):
    """The window seen in ``study handling``: the signal's handler ran inside a weakref callback.

    Both were seen there: SIGTERM (the command's own handler) and Ctrl-C (Python's KeyboardInterrupt,
    now handled by the block as well).

    Python prints an exception raised in a weakref callback as "Exception ignored" and drops
    it, so the study finished with exit status 0. Raising the signal from inside the callback
    makes the handler run exactly there (raise_signal runs pending handlers before returning),
    deterministically. The block must end with Interrupted and print nothing.
    """
    signum = getattr(signal, stop)
    before = signal.getsignal(signum)
    ran = []
    with pytest.raises(Interrupted) as caught:
        with stopping_on_signals():
            thing = _Thing()
            ref = weakref.ref(thing, lambda _ref: (ran.append(True), signal.raise_signal(signum)))
            del thing  # the callback runs here and its exception is swallowed by the interpreter
            assert ref() is None
    assert ran, "the weakref callback did not run: the test exercised nothing"
    assert caught.value.signum == signum
    assert "Exception ignored" not in capsys.readouterr().err
    assert signal.getsignal(signum) is before


def test_an_inherited_ignore_of_ctrl_c_is_respected():
    """A command started with SIGINT ignored (a background job, nohup) keeps ignoring it inside the block."""
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        with stopping_on_signals():
            assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
            signal.raise_signal(signal.SIGINT)  # ignored: the block runs on and ends normally
        assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGINT, previous)
