//! Any bytes from the radio or the UART, fed in arbitrary chunks at arbitrary times into the
//! onboard radio session, the handheld session and the MCU session: nothing panics, and after the
//! junk a genuine handheld still connects and its start is accepted (the sessions resynchronise).
#![no_main]

use libfuzzer_sys::fuzz_target;
use link::handheld::{HandheldConfig, HandheldRadio};
use link::mcu::{McuSession, McuSessionConfig};
use link::radio::{OnboardRadio, RadioRequest};
use link::reliable::LinkConfig;
use link::session::Entropy;
use protocol::auth::{KEY_LEN, Key};
use protocol::bounded::Text;
use protocol::radio::{StartMeasurement, Zone};

fuzz_target!(|data: &[u8]| {
    let key = Key([3; KEY_LEN]);
    let mut onboard = OnboardRadio::new(
        LinkConfig::RADIO,
        vec![key.clone()],
        Entropy::from_test_seed(0),
        5000,
    );
    let mut handheld = HandheldRadio::new(
        HandheldConfig::default(),
        key.clone(),
        Entropy::from_test_seed(100),
        1000,
    );
    handheld.connect(0).expect("a handshake encodes");
    let mcu_config = McuSessionConfig {
        link: LinkConfig::MCU,
        heartbeat_period_us: 20_000,
        resend_us: 200_000,
        firmware: onboard::config::firmware_defaults(),
        accel_mps2: 0.3,
        jerk_mps3: 1.0,
        status_timeout_us: 500_000,
    };
    let mut mcu = McuSession::new(mcu_config, 0);
    let mut now = 0u64;
    for chunk in data.chunks(37) {
        now += u64::from(chunk[0]) * 1_000;
        let _ = onboard.receive(now, chunk);
        let _ = handheld.receive(now, chunk);
        let _ = mcu.receive(now, chunk);
        onboard.poll(now);
        let _ = handheld.poll(now);
        mcu.poll(now);
        let _ = onboard.transmit(now);
        let _ = handheld.transmit(now);
        let _ = mcu.transmit(now);
    }
    // A delimiter ends any partial frame; then a genuine handheld connects and its start gets
    // through.
    let _ = onboard.receive(now, &[0]);
    let mut sender = HandheldRadio::new(
        HandheldConfig::default(),
        key,
        Entropy::from_test_seed(40_000),
        1000,
    );
    let later = now + 120_000_000;
    sender.connect(later).expect("a handshake encodes");
    sender.poll(later);
    let _ = onboard.receive(later, &sender.transmit(later));
    onboard.poll(later);
    let _ = sender.receive(later, &onboard.transmit(later + 1_000_000));
    assert!(sender.is_connected());
    let params = StartMeasurement {
        vehicle_id: Text::truncated("F"),
        speed_mps: 0.2,
        distance_m: 1.0,
        zone: Zone::Tyre,
        lab: protocol::radio::LabRef::NONE,
    };
    sender.start(&params).expect("a start encodes");
    sender.poll(later + 1);
    let requests = onboard.receive(later + 2, &sender.transmit(later + 2));
    assert!(
        requests.iter().any(|r| matches!(r, RadioRequest::Start { .. })),
        "{requests:?}"
    );
});
