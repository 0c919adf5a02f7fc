use oxicat_testkit::device::*;
use oxicat_testkit::{Bench, Port};

fn walk_up_and_down<P: Port>() {
    let mut b = Bench::<P>::new();
    assert_eq!(b.al_status(), (1, 0));
    b.enter_op();
    assert_eq!(b.request(4), (4, 0));
    assert_eq!(b.request(2), (2, 0));
    b.config_pd();
    assert_eq!(b.request(4), (4, 0));
    assert_eq!(b.request(8), (8, 0));
    assert_eq!(b.request(2), (2, 0));
    assert_eq!(b.request(1), (1, 0));
    // From OP straight to INIT.
    b.enter_op();
    assert_eq!(b.request(1), (1, 0));
}

fn invalid_and_unknown_requests<P: Port>() {
    let mut b = Bench::<P>::new();
    b.config_mailbox();
    // INIT -> SAFEOP / OP are invalid.
    assert_eq!(b.request(4), (0x11, 0x0011));
    // Not acknowledged: further requests are ignored.
    assert_eq!(b.request(2), (0x11, 0x0011));
    // Acknowledge together with the request.
    assert_eq!(b.request(0x12), (2, 0));
    // PREOP -> OP invalid.
    assert_eq!(b.request(8), (0x12, 0x0011));
    // Unknown state 5.
    assert_eq!(b.request(0x15), (0x12, 0x0012));
    assert_eq!(b.request(0x12), (2, 0));
    // PREOP -> BOOT invalid, INIT -> BOOT valid (supported).
    assert_eq!(b.request(3), (0x12, 0x0011));
    assert_eq!(b.request(1), (1, 0));
    assert_eq!(b.request(3), (3, 0));
    // BOOT -> PREOP invalid.
    assert_eq!(b.request(2), (0x13, 0x0011));
    assert_eq!(b.request(0x11), (1, 0));
}

fn mailbox_config_checked<P: Port>() {
    let mut b = Bench::<P>::new();
    b.config_sm(0, SM0, 64, 0x26); // wrong length
    b.config_sm(1, SM1, MBX as u16, 0x22);
    assert_eq!(b.request(2), (0x11, 0x0016));
    b.config_mailbox();
    assert_eq!(b.request(0x12), (2, 0));
}

fn process_data_config_checked<P: Port>() {
    let mut b = Bench::<P>::new();
    b.enter_preop();
    let (o, i) = (b.expected_out(), b.expected_in());
    assert_eq!((o, i), (4, 7));
    b.config_sm(2, SM2, o + 1, 0x64);
    b.config_sm(3, SM3, i, 0x20);
    assert_eq!(b.request(4), (0x12, 0x001D));
    b.config_sm(2, SM2, o, 0x64);
    b.config_sm(3, SM3, i - 1, 0x20);
    assert_eq!(b.request(0x14), (0x12, 0x001E));
    b.config_sm(3, SM3, i, 0x20);
    assert_eq!(b.request(0x14), (4, 0));
}

fn application_may_refuse<P: Port>() {
    let mut b = Bench::<P>::new();
    b.enter_safeop();
    b.download(0x2000, 0, false, &999u32.to_le_bytes()).unwrap();
    assert_eq!(b.request(8), (0x14, 0x8001));
    b.download(0x2000, 0, false, &5u32.to_le_bytes()).unwrap();
    assert_eq!(b.request(0x18), (8, 0));
}

fn sync_config_checked<P: Port>() {
    let mut b = Bench::<P>::new();
    b.enter_preop();
    b.config_pd();
    // DC sync requested in 0x1C32 but DC not activated.
    b.download(0x1C32, 1, false, &2u16.to_le_bytes()).unwrap();
    assert_eq!(b.request(4), (0x12, 0x0030));
    // Unsupported value is refused by the SDO server.
    assert_eq!(
        b.download(0x1C32, 1, false, &7u16.to_le_bytes()),
        Err(0x0609_0030)
    );
    b.download(0x1C32, 1, false, &0u16.to_le_bytes()).unwrap();
    assert_eq!(b.request(0x14), (4, 0));
}

fn process_data_free_run<P: Port>() {
    let mut b = Bench::<P>::new();
    b.enter_op();
    // Outputs: LED bit 0, Setpoint at byte 1..2, Mode at byte 3.
    assert_eq!(b.wr(SM2, &[0x01, 0x34, 0x12, 0x07]), 1);
    b.poll();
    assert_eq!(b.s.od().get::<i16>(0x7000, 2), Ok(0x1234));
    assert_eq!(b.s.od().get::<bool>(0x7000, 1), Ok(true));
    assert_eq!(b.s.od().get::<u8>(0x7000, 3), Ok(7));
    let (d, wkc) = b.rd(SM3, 7);
    assert_eq!(wkc, 1);
    // Button 2 (bit 1) = LED, Analog = 2 * setpoint, counter.
    assert_eq!(d[0] & 0x02, 0x02);
    assert_eq!(i16::from_le_bytes([d[1], d[2]]), 0x2468);
    assert!(u32::from_le_bytes([d[3], d[4], d[5], d[6]]) > 0);
}

fn outputs_ignored_in_safeop<P: Port>() {
    let mut b = Bench::<P>::new();
    b.enter_safeop();
    assert_eq!(b.wr(SM2, &[0x01, 0x34, 0x12, 0x07]), 1);
    b.poll();
    assert_eq!(b.s.od().get::<i16>(0x7000, 2), Ok(0));
}

fn sm_watchdog_drops_to_safeop<P: Port>() {
    let mut b = Bench::<P>::new();
    b.enter_preop();
    b.config_pd();
    // 100 ms watchdog at the default divider (100 us units).
    b.wr(0x0420, &1000u16.to_le_bytes());
    assert_eq!(b.request(4), (4, 0));
    assert_eq!(b.request(8), (8, 0));
    b.wr(SM2, &[0x01, 0x10, 0x00, 0x01]);
    b.poll();
    assert_eq!(b.s.od().get::<i16>(0x7000, 2), Ok(0x10));
    let safe_before = b.app.safe;
    b.advance(200_000_000);
    b.poll();
    assert_eq!(b.al_status(), (0x14, 0x001B));
    assert!(b.app.safe > safe_before);
    assert_eq!(b.s.od().get::<i16>(0x7000, 2), Ok(0));
    // Inputs keep updating in SAFEOP.
    let c0 = b.s.stats().cycles;
    b.poll();
    assert!(b.s.stats().cycles > c0);
    // Acknowledge, outputs again, OP.
    assert_eq!(b.request(0x14), (4, 0));
    b.wr(SM2, &[0x01, 0x10, 0x00, 0x01]);
    assert_eq!(b.request(8), (8, 0));
}

/// SM change AL event outside a state change: SM2/SM3 re-checked against the running
/// mapping in SAFEOP/OP (PREOP + 0x001D / 0x001E), the mailbox SMs against the definition
/// (INIT + 0x0016), as SOES does.
fn sm_change_rechecked<P: Port>() {
    let mut b = Bench::<P>::new();
    b.enter_op();
    let (o, i) = (b.expected_out(), b.expected_in());
    // The same configuration written again (deactivated and re-activated before the
    // firmware looks): still valid, stays in OP.
    b.config_sm(2, SM2, 0, 0x64);
    b.config_sm(2, SM2, o, 0x64);
    b.poll();
    assert_eq!(b.al_status(), (8, 0));
    // SM2 deactivated in OP: outputs go safe, PREOP + invalid output configuration.
    let safe = b.app.safe;
    b.config_sm(2, SM2, 0, 0x64);
    b.poll();
    assert_eq!(b.al_status(), (0x12, 0x001D));
    assert!(b.app.safe > safe, "safe outputs applied");
    assert_eq!(b.s.state(), oxicat_slave::AlState::PreOp);
    // Acknowledge, back up to SAFEOP; then SM3 re-enabled with another length.
    assert_eq!(b.request(0x12), (2, 0));
    b.config_pd();
    assert_eq!(b.request(4), (4, 0));
    b.config_sm(3, SM3, 0, 0x20);
    b.config_sm(3, SM3, i + 2, 0x20);
    b.poll();
    assert_eq!(b.al_status(), (0x12, 0x001E));
    // In PREOP, SM2/SM3 changes are the master's business (no error).
    assert_eq!(b.request(0x12), (2, 0));
    b.config_sm(2, SM2, 0, 0x64);
    b.config_sm(3, SM3, 0, 0x20);
    b.poll();
    assert_eq!(b.al_status(), (2, 0));
    // The mailbox SMs are checked in PREOP and above: SM1 deactivated -> INIT + 0x0016.
    b.config_sm(1, SM1, 0, 0x22);
    b.poll();
    assert_eq!(b.al_status(), (0x11, 0x0016));
    b.config_mailbox();
    assert_eq!(b.request(0x12), (2, 0));
    // Mailbox still serves.
    assert_eq!(b.upload(0x1018, 1, false).unwrap(), 0x0A5Cu32.to_le_bytes());
}

/// Issue 15: a board whose main loop polls with the ESC interrupts masked makes PREOP ->
/// SAFEOP in three polls ((`Slave::set_stepwise_safeop`)): the AL status answers after the
/// third, with the same checks as in one poll, and the process data then runs.
fn stepwise_safeop_takes_three_polls_and_checks_the_same<P: Port>() {
    let one = |b: &mut Bench<P>| b.s.poll(&mut b.drv, &mut b.app).unwrap();
    let mut b = Bench::<P>::new();
    b.s.set_stepwise_safeop(true);
    b.enter_preop();
    let (o, i) = (b.expected_out(), b.expected_in());
    // A wrong SM2 length: refused after the third poll, as in one.
    b.config_sm(2, SM2, o + 1, 0x64);
    b.config_sm(3, SM3, i, 0x20);
    b.wr(0x0120, &4u16.to_le_bytes());
    one(&mut b);
    one(&mut b);
    assert_eq!(
        b.al_status(),
        (2, 0),
        "{}: still PREOP, no answer yet",
        P::NAME
    );
    one(&mut b);
    assert_eq!(b.al_status(), (0x12, 0x001D), "{}", P::NAME);
    b.config_sm(2, SM2, o, 0x64);
    b.wr(0x0120, &0x14u16.to_le_bytes());
    one(&mut b);
    assert_eq!(
        b.al_status(),
        (0x12, 0x001D),
        "{}: the request waits",
        P::NAME
    );
    one(&mut b);
    one(&mut b);
    assert_eq!(b.al_status(), (4, 0), "{}", P::NAME);
    assert_eq!(b.request(8), (8, 0));
    assert_eq!(b.wr(SM2, &[0x01, 0x34, 0x12, 0x07]), 1);
    b.poll();
    assert_eq!(b.s.od().get::<i16>(0x7000, 2), Ok(0x1234));
    // Down and up again, in the usual three polls of `request`.
    assert_eq!(b.request(2), (2, 0));
    assert_eq!(b.request(4), (4, 0));
}

oxicat_testkit::every_pdi!(
    walk_up_and_down,
    invalid_and_unknown_requests,
    mailbox_config_checked,
    process_data_config_checked,
    application_may_refuse,
    sync_config_checked,
    process_data_free_run,
    outputs_ignored_in_safeop,
    sm_watchdog_drops_to_safeop,
    sm_change_rechecked,
    stepwise_safeop_takes_three_polls_and_checks_the_same,
);
