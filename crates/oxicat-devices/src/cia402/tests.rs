//! State-machine level tests: every transition 0–16, the command masks, the statusword
//! decoding and every option code (0x605A–0x605E).

use super::fsm::{Command, Events, Fsm, Options, Ramp, State, Stop};
use State::*;

const NONE: Events = Events {
    fault: false,
    stopped: false,
};
const STOPPED: Events = Events {
    fault: false,
    stopped: true,
};
const FAULT: Events = Events {
    fault: true,
    stopped: false,
};

/// A machine brought to `s` by the ordinary commands.
fn reach(s: State, opt: &Options) -> Fsm {
    let mut f = Fsm::new();
    let path: &[(u16, Events)] = match s {
        NotReadyToSwitchOn => &[],
        SwitchOnDisabled => &[(0, NONE)],
        ReadyToSwitchOn => &[(0, NONE), (0x06, NONE)],
        SwitchedOn => &[(0, NONE), (0x06, NONE), (0x07, NONE)],
        OperationEnabled => &[(0, NONE), (0x06, NONE), (0x07, NONE), (0x0F, NONE)],
        QuickStopActive => &[
            (0, NONE),
            (0x06, NONE),
            (0x07, NONE),
            (0x0F, NONE),
            (0x02, NONE),
        ],
        FaultReactionActive => &[(0, NONE), (0x06, NONE), (0x0F, FAULT)],
        Fault => &[(0, NONE), (0x06, NONE), (0x0F, FAULT), (0x06, STOPPED)],
    };
    for &(c, e) in path {
        f.step(c, e, opt);
    }
    assert_eq!(f.state(), s, "could not reach {s:?}");
    f
}

fn opts(f: impl FnOnce(&mut Options)) -> Options {
    let mut o = Options::default();
    f(&mut o);
    o
}

#[test]
fn transitions_0_and_1_are_automatic() {
    let mut f = Fsm::new();
    assert_eq!(f.state(), NotReadyToSwitchOn, "transition 0: power on");
    assert_eq!(f.step(0, NONE, &Options::default()), Some(1));
    assert_eq!(f.state(), SwitchOnDisabled);
}

/// (from, options, controlword, events, expected transition, expected state).
type Row = (State, Options, u16, Events, Option<u8>, State);

#[test]
fn every_transition_by_its_command() {
    let d = Options::default();
    let coast = opts(|o| {
        o.disable_operation = 0;
        o.shutdown = 0;
    });
    let stays = opts(|o| o.quick_stop = 6);
    let rows: &[Row] = &[
        (SwitchOnDisabled, d, 0x06, NONE, Some(2), ReadyToSwitchOn),
        (SwitchOnDisabled, d, 0x0E, NONE, Some(2), ReadyToSwitchOn), // bit 3 don't care
        (ReadyToSwitchOn, d, 0x07, NONE, Some(3), SwitchedOn),
        (ReadyToSwitchOn, d, 0x0F, NONE, Some(3), SwitchedOn), // then 4 on the next step
        (SwitchedOn, d, 0x0F, NONE, Some(4), OperationEnabled),
        (OperationEnabled, coast, 0x07, NONE, Some(5), SwitchedOn),
        (SwitchedOn, d, 0x06, NONE, Some(6), ReadyToSwitchOn),
        (ReadyToSwitchOn, d, 0x00, NONE, Some(7), SwitchOnDisabled),
        (ReadyToSwitchOn, d, 0x02, NONE, Some(7), SwitchOnDisabled),
        (
            OperationEnabled,
            coast,
            0x06,
            NONE,
            Some(8),
            ReadyToSwitchOn,
        ),
        (OperationEnabled, d, 0x00, NONE, Some(9), SwitchOnDisabled),
        (OperationEnabled, d, 0x0D, NONE, Some(9), SwitchOnDisabled), // bit 1 = 0
        (SwitchedOn, d, 0x00, NONE, Some(10), SwitchOnDisabled),
        (SwitchedOn, d, 0x02, NONE, Some(10), SwitchOnDisabled),
        (OperationEnabled, d, 0x02, NONE, Some(11), QuickStopActive),
        (
            QuickStopActive,
            stays,
            0x00,
            NONE,
            Some(12),
            SwitchOnDisabled,
        ),
        (
            QuickStopActive,
            d,
            0x02,
            STOPPED,
            Some(12),
            SwitchOnDisabled,
        ), // options 1–4: auto
        (
            SwitchOnDisabled,
            d,
            0x00,
            FAULT,
            Some(13),
            FaultReactionActive,
        ),
        (
            OperationEnabled,
            d,
            0x0F,
            FAULT,
            Some(13),
            FaultReactionActive,
        ),
        (
            QuickStopActive,
            stays,
            0x02,
            FAULT,
            Some(13),
            FaultReactionActive,
        ),
        (FaultReactionActive, d, 0x0F, STOPPED, Some(14), Fault),
        (Fault, d, 0x80, NONE, Some(15), SwitchOnDisabled),
        (
            QuickStopActive,
            stays,
            0x0F,
            NONE,
            Some(16),
            OperationEnabled,
        ),
        // Commands that are no transition of the state.
        (SwitchOnDisabled, d, 0x07, NONE, None, SwitchOnDisabled),
        (SwitchOnDisabled, d, 0x0F, NONE, None, SwitchOnDisabled),
        (QuickStopActive, d, 0x0F, NONE, None, QuickStopActive), // option 2: no 16
        (Fault, d, 0x0F, NONE, None, Fault),
    ];
    for (i, &(from, opt, cw, ev, t, to)) in rows.iter().enumerate() {
        let mut f = reach(from, &opt);
        let got = f.step(cw, ev, &opt);
        assert_eq!(
            (got, f.state()),
            (t, to),
            "row {i}: {from:?} + {cw:#06x} {ev:?}"
        );
    }
}

#[test]
fn switch_on_plus_enable_operation_goes_through_3_then_4() {
    let o = Options::default();
    let mut f = reach(ReadyToSwitchOn, &o);
    assert_eq!(f.step(0x0F, NONE, &o), Some(3));
    assert_eq!(f.step(0x0F, NONE, &o), Some(4));
    assert_eq!(f.state(), OperationEnabled);
}

#[test]
fn fault_reset_acts_on_the_rising_edge_only() {
    let o = Options::default();
    let mut f = reach(Fault, &o);
    // Bit 7 rising (the last command was 0x06): reset.
    let mut g = f;
    assert_eq!(g.step(0x80, NONE, &o), Some(15));
    // A fault still present at the edge keeps the drive in Fault (13 does not retrigger).
    let mut h = f;
    assert_eq!(h.step(0x80, FAULT, &o), None);
    assert_eq!(h.state(), Fault);
    // Bit 7 stays high: no second edge, nothing happens.
    assert_eq!(h.step(0x80, NONE, &o), None);
    assert_eq!(h.state(), Fault);
    // Low, then high again: reset.
    assert_eq!(h.step(0x00, NONE, &o), None);
    assert_eq!(h.step(0x80, NONE, &o), Some(15));
    // Bit 7 high in an ordinary state is no device control command.
    assert_eq!(f.step(0x00, NONE, &o), None);
    let mut e = reach(SwitchedOn, &o);
    assert_eq!(e.step(0x8F, NONE, &o), None);
    assert_eq!(e.state(), SwitchedOn);
}

#[test]
fn commands_decode_by_their_masks() {
    for cw in 0u16..=0xFF {
        let expect = if cw & 0x80 != 0 {
            Command::FaultReset
        } else if cw & 0x82 == 0x00 {
            Command::DisableVoltage
        } else if cw & 0x86 == 0x02 {
            Command::QuickStop
        } else if cw & 0x87 == 0x06 {
            Command::Shutdown
        } else if cw & 0x8F == 0x07 {
            Command::SwitchOn
        } else {
            assert_eq!(cw & 0x8F, 0x0F);
            Command::EnableOperation
        };
        assert_eq!(Command::decode(cw), expect, "{cw:#04x}");
        // Bits 4–15 other than 7 never change the command.
        assert_eq!(Command::decode(cw | 0xFF70 & !0x80), Command::decode(cw));
    }
}

#[test]
fn statusword_decodes_to_every_state_and_0x4663_to_none() {
    for s in [
        NotReadyToSwitchOn,
        SwitchOnDisabled,
        ReadyToSwitchOn,
        SwitchedOn,
        OperationEnabled,
        QuickStopActive,
        FaultReactionActive,
        Fault,
    ] {
        let w = s.statusword_bits();
        assert_eq!(State::decode(w), Some(s));
        // Remote, target reached, mode bits do not disturb the decoding.
        assert_eq!(
            State::decode(w | 0xFE80 & !0x0040 & !0x0020 | (w & 0x60)),
            Some(s)
        );
    }
    // The paper's "Operation enabled" value: bit 2 clear, bit 6 set: no state.
    assert_eq!(State::decode(0x4663), None);
    assert_eq!(State::decode(0x4637), Some(OperationEnabled));
}

#[test]
fn quick_stop_option_codes() {
    let table: &[(i16, Ramp, bool)] = &[
        (0, Ramp::Coast, false),
        (1, Ramp::SlowDown, false),
        (2, Ramp::QuickStop, false),
        (3, Ramp::CurrentLimit, false),
        (4, Ramp::VoltageLimit, false),
        (5, Ramp::SlowDown, true),
        (6, Ramp::QuickStop, true),
        (7, Ramp::CurrentLimit, true),
        (8, Ramp::VoltageLimit, true),
    ];
    for &(code, ramp, stays) in table {
        let o = opts(|o| o.quick_stop = code);
        let mut f = reach(OperationEnabled, &o);
        assert_eq!(f.step(0x02, NONE, &o), Some(11), "code {code}");
        assert_eq!(f.state(), QuickStopActive);
        if code == 0 {
            // Drive function disabled at once, then on to Switch on disabled.
            assert_eq!(f.stopping().unwrap().ramp, Ramp::Coast);
            assert_eq!(f.step(0x02, NONE, &o), Some(12));
            continue;
        }
        assert_eq!(
            f.stopping(),
            Some(Stop {
                ramp,
                then: (!stays).then_some(12)
            }),
            "code {code}"
        );
        // Still moving: stays in Quick stop active.
        assert_eq!(f.step(0x02, NONE, &o), None);
        // At rest: 1–4 go on to Switch on disabled, 5–8 stay (and allow 16).
        let t = f.step(0x02, STOPPED, &o);
        if stays {
            assert_eq!((t, f.state()), (None, QuickStopActive), "code {code}");
            assert_eq!(f.step(0x0F, NONE, &o), Some(16));
        } else {
            assert_eq!((t, f.state()), (Some(12), SwitchOnDisabled), "code {code}");
        }
    }
}

#[test]
fn shutdown_and_disable_operation_option_codes() {
    for (cw, t, to) in [(0x06u16, 8u8, ReadyToSwitchOn), (0x07, 5, SwitchedOn)] {
        for code in [0i16, 1] {
            let o = opts(|o| {
                o.shutdown = code;
                o.disable_operation = code;
            });
            let mut f = reach(OperationEnabled, &o);
            let got = f.step(cw, NONE, &o);
            if code == 0 {
                assert_eq!(
                    (got, f.state()),
                    (Some(t), to),
                    "cw {cw:#x} code 0 disables at once"
                );
            } else {
                // Slow down ramp first; the state stays Operation enabled until at rest.
                assert_eq!((got, f.state()), (None, OperationEnabled));
                assert_eq!(
                    f.stopping(),
                    Some(Stop {
                        ramp: Ramp::SlowDown,
                        then: Some(t)
                    })
                );
                assert_eq!(f.step(cw, NONE, &o), None);
                assert_eq!(f.step(cw, STOPPED, &o), Some(t));
                assert_eq!(f.state(), to);
            }
        }
    }
    // An enable during the ramp cancels it.
    let o = opts(|o| o.disable_operation = 1);
    let mut f = reach(OperationEnabled, &o);
    f.step(0x07, NONE, &o);
    assert!(f.stopping().is_some());
    f.step(0x0F, NONE, &o);
    assert_eq!((f.state(), f.stopping()), (OperationEnabled, None));
}

#[test]
fn halt_and_fault_reaction_option_codes() {
    assert_eq!(Options::halt_ramp(1), Ramp::SlowDown);
    assert_eq!(Options::halt_ramp(2), Ramp::QuickStop);
    assert_eq!(Options::halt_ramp(3), Ramp::CurrentLimit);
    assert_eq!(Options::halt_ramp(4), Ramp::VoltageLimit);
    let table = [
        (0i16, Ramp::Coast),
        (1, Ramp::SlowDown),
        (2, Ramp::QuickStop),
        (3, Ramp::CurrentLimit),
        (4, Ramp::VoltageLimit),
    ];
    for (code, ramp) in table {
        let o = opts(|o| o.fault_reaction = code);
        let mut f = reach(OperationEnabled, &o);
        assert_eq!(f.step(0x0F, FAULT, &o), Some(13));
        assert_eq!(
            f.stopping(),
            Some(Stop {
                ramp,
                then: Some(14)
            })
        );
        if code == 0 {
            assert_eq!(f.step(0x0F, NONE, &o), Some(14), "coast: straight to Fault");
        } else {
            assert_eq!(f.step(0x0F, NONE, &o), None, "ramp {code} still running");
            assert_eq!(f.step(0x0F, STOPPED, &o), Some(14));
        }
        assert_eq!(f.state(), Fault);
    }
    // A fault while not powered has nothing to stop.
    let o = Options::default();
    let mut f = reach(SwitchedOn, &o);
    assert_eq!(f.step(0x07, FAULT, &o), Some(13));
    assert_eq!(f.stopping().unwrap().ramp, Ramp::Coast);
    assert_eq!(f.step(0x07, NONE, &o), Some(14));
}
