//! The frame assembler on synthetic packets built with `DataPacketRepr::emit`: exact geometry and
//! timing, dual returns, cut angles, range limits, malformed packets, the hour wrap, and a
//! never-panics property over mutated packets.

#![allow(clippy::unwrap_used)]

use proptest::prelude::*;
use vlp16::decoder::{CYCLE_US, ELEVATION_DEG, FIRING_US, SEQUENCE_US, VERTICAL_OFFSET_MM};
use vlp16::{
    BlockRepr, ChannelRepr, DataPacketRepr, DecodeError, DecoderConfig, Frame, FrameAssembler,
    PacketError, Product, ReturnKind, ReturnMode,
};

/// A packet whose block `b` has azimuth `start_raw + b * step_raw` (mod 36000) and every channel
/// at `distance_raw` with reflectivity = channel index.
fn packet(start_raw: u32, step_raw: u32, distance_raw: u16, timestamp_us: u32) -> DataPacketRepr {
    let mut blocks = [BlockRepr::default(); 12];
    for (b, block) in blocks.iter_mut().enumerate() {
        block.azimuth_raw = ((start_raw + b as u32 * step_raw) % 36_000) as u16;
        for (c, ch) in block.channels.iter_mut().enumerate() {
            *ch = ChannelRepr {
                distance_raw,
                reflectivity: c as u8,
            };
        }
    }
    DataPacketRepr {
        blocks,
        timestamp_us,
        return_mode: ReturnMode::Strongest,
        product: Product::Vlp16,
    }
}

fn drain(assembler: &mut FrameAssembler) -> Vec<Frame> {
    std::iter::from_fn(|| assembler.pop_frame()).collect()
}

fn finish(mut assembler: FrameAssembler) -> (Vec<Frame>, FrameAssembler) {
    assembler.finish();
    (drain(&mut assembler), assembler)
}

#[test]
fn geometry_and_timing_of_every_firing_match_the_manual() {
    let repr = packet(1_000, 20, 5_000, 7_000);
    let mut asm = FrameAssembler::new(DecoderConfig::default()).unwrap();
    asm.push_data(&repr.to_bytes(), 42).unwrap();
    let (frames, _) = finish(asm);
    assert_eq!(frames.len(), 1);
    let frame = &frames[0];
    assert_eq!(frame.points.len(), 384);
    assert_eq!(frame.start_host_ns, 42);
    assert!((frame.start_sensor_us - 7_000.0).abs() < 1e-9);
    for (i, p) in frame.points.iter().enumerate() {
        let (block, channel) = (i / 32, i % 32);
        let (seq, laser) = (channel / 16, channel % 16);
        let offset_us = SEQUENCE_US * seq as f64 + FIRING_US * laser as f64;
        // Independent evaluation in f64 of the manual's formulas.
        let azimuth_deg = (1_000.0 + 20.0 * block as f64 + 20.0 * offset_us / CYCLE_US) / 100.0;
        let (a, w) = (
            azimuth_deg.to_radians(),
            f64::from(ELEVATION_DEG[laser]).to_radians(),
        );
        let r = 10.0;
        let expected = [
            r * w.cos() * a.sin(),
            r * w.cos() * a.cos(),
            r * w.sin() + f64::from(VERTICAL_OFFSET_MM[laser]) * 1e-3,
        ];
        let got = [f64::from(p.x_m), f64::from(p.y_m), f64::from(p.z_m)];
        for axis in 0..3 {
            assert!(
                (got[axis] - expected[axis]).abs() < 5e-6,
                "point {i} axis {axis}"
            );
        }
        let t = CYCLE_US * block as f64 + offset_us;
        assert!((f64::from(p.time_us) - t).abs() < 1e-3, "time of point {i}");
        assert!((f64::from(p.azimuth_rad) - a).abs() < 1e-6);
        assert_eq!(usize::from(p.laser_id), laser);
        assert_eq!(p.intensity as usize, channel);
        assert_eq!(p.return_kind, ReturnKind::Strongest);
    }
    // Rings sort by elevation: ring 0 is -15 deg, ring 15 is +15 deg.
    let mut by_ring = [f32::NAN; 16];
    for p in &frame.points[..16] {
        by_ring[usize::from(p.ring)] = ELEVATION_DEG[usize::from(p.laser_id)];
    }
    assert!(by_ring.windows(2).all(|w| w[0] < w[1]), "{by_ring:?}");
}

#[test]
fn last_block_reuses_the_previous_gap() {
    // Gaps of 10, 10, ..., then the last block must interpolate with 10 too, whatever the next
    // packet does.
    let repr = packet(0, 10, 500, 0);
    let mut asm = FrameAssembler::new(DecoderConfig::default()).unwrap();
    asm.push_data(&repr.to_bytes(), 0).unwrap();
    let (frames, _) = finish(asm);
    let last = frames[0].points.last().unwrap(); // block 11, seq 1, laser 15
    let expected_raw = 110.0 + 10.0 * (SEQUENCE_US + 15.0 * FIRING_US) / CYCLE_US;
    assert!((f64::from(last.azimuth_rad) - (expected_raw / 100.0).to_radians()).abs() < 1e-6);
}

#[test]
fn dual_returns_pair_blocks_and_drop_identical_echoes() {
    let mut repr = packet(0, 0, 0, 0);
    repr.return_mode = ReturnMode::Dual;
    for k in 0..6 {
        let azimuth_raw = (k * 20) as u16;
        repr.blocks[2 * k].azimuth_raw = azimuth_raw;
        repr.blocks[2 * k + 1].azimuth_raw = azimuth_raw;
        for c in 0..32 {
            // Even block: last return at 4 m, reflectivity 10.
            repr.blocks[2 * k].channels[c] = ChannelRepr {
                distance_raw: 2_000,
                reflectivity: 10,
            };
            // Odd block: channel 0 repeats the last (one echo), channel 1 a stronger nearer echo,
            // the rest a weaker one (the last was the strongest).
            repr.blocks[2 * k + 1].channels[c] = match c {
                0 => ChannelRepr {
                    distance_raw: 2_000,
                    reflectivity: 10,
                },
                1 => ChannelRepr {
                    distance_raw: 1_000,
                    reflectivity: 90,
                },
                _ => ChannelRepr {
                    distance_raw: 1_500,
                    reflectivity: 5,
                },
            };
        }
    }
    let mut asm = FrameAssembler::new(DecoderConfig::default()).unwrap();
    asm.push_data(&repr.to_bytes(), 0).unwrap();
    let (frames, asm) = finish(asm);
    let points = &frames[0].points;
    // 6 cycles x 32 channels, each with two returns except channel 0 (one echo).
    assert_eq!(points.len(), 6 * (32 * 2 - 1));
    assert_eq!(asm.stats().dual_duplicates, 6);
    assert_eq!(asm.stats().return_modes, [0, 0, 1]);
    let kinds = |kind| points.iter().filter(|p| p.return_kind == kind).count();
    assert_eq!(kinds(ReturnKind::Last), 6 * 32);
    assert_eq!(kinds(ReturnKind::Strongest), 6);
    assert_eq!(kinds(ReturnKind::SecondStrongest), 6 * 30);
    // Both returns of a firing share its time; cycle k starts at k * 110.592 us.
    let last_cycle: Vec<_> = points.iter().filter(|p| p.time_us > 5.0 * 110.0).collect();
    assert!((f64::from(last_cycle[0].time_us) - 5.0 * CYCLE_US).abs() < 1e-3);
    // Laser 0 has one echo (channel 0 repeated); laser 1's two returns share its firing time.
    assert_eq!(
        last_cycle[1].time_us.to_bits(),
        last_cycle[2].time_us.to_bits()
    );
    assert!((f64::from(last_cycle[1].time_us) - 5.0 * CYCLE_US - FIRING_US).abs() < 1e-3);
}

#[test]
fn frames_cut_at_the_configured_angle() {
    let config = DecoderConfig {
        cut_azimuth_rad: 90f32.to_radians(),
        ..DecoderConfig::default()
    };
    let mut asm = FrameAssembler::new(config).unwrap();
    // 0.4 deg per cycle (1200 rpm): 75 packets per revolution; 200 packets from 0 deg.
    for k in 0..200u32 {
        let repr = packet(k * 12 * 40, 40, 1_000, k * 1_327);
        asm.push_data(&repr.to_bytes(), u64::from(k)).unwrap();
    }
    let (frames, _) = finish(asm);
    assert_eq!(frames.len(), 4);
    assert!(!frames[0].starts_at_cut && frames[0].ends_at_cut);
    for f in &frames[1..3] {
        assert!(f.is_complete());
        assert_eq!(f.points.len(), 900 * 32); // 360 / 0.4 cycles
        let first = f64::from(f.points[0].azimuth_rad).to_degrees();
        assert!(
            (first - 90.0).abs() < 1e-3,
            "frame {} starts at {first} deg",
            f.index
        );
        let rpm = f.rpm().unwrap();
        assert!(
            (rpm - 0.4 / 360.0 / (CYCLE_US * 1e-6) * 60.0).abs() < 1.0,
            "{rpm}"
        );
    }
    assert!(frames[3].starts_at_cut && !frames[3].ends_at_cut);
    let total: usize = frames.iter().map(|f| f.points.len()).sum();
    assert_eq!(total, 200 * 384);
}

#[test]
fn a_late_packet_does_not_cut_a_frame() {
    let mut asm = FrameAssembler::new(DecoderConfig::default()).unwrap();
    let order = [0u32, 1, 2, 4, 3, 5, 6]; // packet 3 arrives after packet 4
    for k in order {
        let repr = packet(1_000 + k * 12 * 20, 20, 1_000, k * 1_327);
        asm.push_data(&repr.to_bytes(), 0).unwrap();
    }
    let (frames, _) = finish(asm);
    assert_eq!(frames.len(), 1);
    assert_eq!(frames[0].points.len(), 7 * 384);
    assert_eq!(frames[0].packets, 7);
}

#[test]
fn range_offsets_move_each_lasers_returns_along_its_ray() {
    let offsets: [f32; 16] = std::array::from_fn(|l| 0.001 * l as f32 - 0.005);
    let plain = FrameAssembler::new(DecoderConfig::default()).unwrap();
    let calibrated = FrameAssembler::new(DecoderConfig {
        range_offsets_m: offsets,
        ..DecoderConfig::default()
    })
    .unwrap();
    let decode = |mut asm: FrameAssembler| {
        asm.push_data(&packet(0, 20, 2_500, 0).to_bytes(), 0)
            .unwrap();
        finish(asm).0.remove(0).points
    };
    let (a, b) = (decode(plain), decode(calibrated));
    assert_eq!(a.len(), b.len());
    for (p, q) in a.iter().zip(&b) {
        let l = usize::from(p.laser_id);
        let z0 = VERTICAL_OFFSET_MM[l] * 1e-3;
        let r = |p: &vlp16::Point| (p.x_m.powi(2) + p.y_m.powi(2) + (p.z_m - z0).powi(2)).sqrt();
        assert!((r(p) - 5.0).abs() < 1e-5, "{}", r(p));
        assert!(
            (r(p) - r(q) - offsets[l]).abs() < 1e-5,
            "laser {l}: {} {}",
            r(p),
            r(q)
        );
        // Along the same ray.
        assert!((p.azimuth_rad - q.azimuth_rad).abs() < 1e-7);
        assert!(((p.z_m - z0) / r(p) - (q.z_m - z0) / r(q)).abs() < 1e-6);
    }
    for bad in [f32::NAN, 0.2, -0.11] {
        let mut o = [0.0; 16];
        o[3] = bad;
        let e = FrameAssembler::new(DecoderConfig {
            range_offsets_m: o,
            ..DecoderConfig::default()
        })
        .unwrap_err();
        assert!(e.to_string().contains("range_offsets_m[3]"), "{e}");
    }
}

#[test]
fn range_limits_drop_and_count() {
    let config = DecoderConfig {
        min_range_m: 1.0,
        max_range_m: 2.0,
        ..DecoderConfig::default()
    };
    let mut asm = FrameAssembler::new(config).unwrap();
    for (k, distance_raw) in [(0u32, 499u16), (1, 500), (2, 1_000), (3, 1_001), (4, 0)] {
        let repr = packet(k * 240, 20, distance_raw, k * 1_327);
        asm.push_data(&repr.to_bytes(), 0).unwrap();
    }
    let (frames, asm) = finish(asm);
    assert_eq!(
        frames.iter().map(|f| f.points.len()).sum::<usize>(),
        2 * 384
    );
    assert_eq!(asm.stats().out_of_range, 2 * 384);
    assert_eq!(asm.stats().zero_returns, 384);
    assert!(
        DecoderConfig {
            min_range_m: 3.0,
            ..config
        }
        .check()
        .is_err()
    );
    assert!(
        FrameAssembler::new(DecoderConfig {
            cut_azimuth_rad: 7.0,
            ..config
        })
        .is_err()
    );
}

#[test]
fn malformed_packets_are_counted_by_reason_and_change_nothing_else() {
    let mut asm = FrameAssembler::new(DecoderConfig::default()).unwrap();
    let good = packet(0, 20, 1_000, 0).to_bytes();
    asm.push_data(&good, 0).unwrap();
    let before = (asm.stats().points, asm.stats().data_packets);

    assert_eq!(
        asm.push_data(&good[..1000], 0),
        Err(DecodeError::Packet(PacketError::WrongLength { len: 1000 }))
    );
    let mut bad = good;
    bad[300] = 0;
    assert!(matches!(
        asm.push_data(&bad, 0),
        Err(DecodeError::Packet(PacketError::BadBlockFlag {
            block: 3,
            ..
        }))
    ));
    let mut bad = good;
    bad[402..404].copy_from_slice(&40_000u16.to_le_bytes());
    assert!(matches!(
        asm.push_data(&bad, 0),
        Err(DecodeError::Packet(PacketError::AzimuthOutOfRange {
            block: 4,
            ..
        }))
    ));
    let mut bad = good;
    bad[502..504].copy_from_slice(&9_000u16.to_le_bytes()); // 90 deg jump inside a packet
    let err = asm.push_data(&bad, 0).unwrap_err();
    assert_eq!(
        err,
        DecodeError::AzimuthJump {
            block: 5,
            from_raw: 80,
            to_raw: 9_000
        }
    );
    assert!(err.to_string().contains("block 5"));
    let mut dual = packet(0, 20, 1_000, 0);
    dual.return_mode = ReturnMode::Dual;
    let err = asm.push_data(&dual.to_bytes(), 0).unwrap_err();
    assert_eq!(
        err,
        DecodeError::DualPairMismatch {
            block: 0,
            first_raw: 0,
            second_raw: 20
        }
    );

    let stats = asm.stats();
    assert_eq!((stats.points, stats.data_packets), before);
    assert_eq!(
        stats.malformed_data,
        vec![
            ("wrong-length", 1),
            ("bad-block-flag", 1),
            ("azimuth-out-of-range", 1),
            ("azimuth-jump", 1),
            ("dual-pair-mismatch", 1)
        ]
    );
    assert_eq!(stats.malformed_data_total(), 5);
    assert!(asm.push_position(&[0u8; 100]).is_err());
    assert_eq!(asm.stats().malformed_position, 1);
}

#[test]
fn point_times_run_on_across_the_hour_wrap() {
    let mut asm = FrameAssembler::new(DecoderConfig::default()).unwrap();
    let hour_us: u32 = 3_600_000_000;
    let first = packet(0, 20, 1_000, hour_us - 1_000);
    let second = packet(240, 20, 1_000, 327); // 1327 us later, after the wrap
    asm.push_data(&first.to_bytes(), 0).unwrap();
    asm.push_data(&second.to_bytes(), 0).unwrap();
    let (frames, _) = finish(asm);
    let p = &frames[0].points[384];
    assert!(
        (f64::from(p.time_us) - 1_327.0).abs() < 1e-3,
        "{}",
        p.time_us
    );
    assert_eq!(frames[0].packets, 2);
    assert!((frames[0].duration_us - (1_327.0 + 11.0 * CYCLE_US + SEQUENCE_US)).abs() < 1e-6);
}

#[test]
fn old_firmware_product_byte_is_decoded_and_counted() {
    let mut repr = packet(0, 20, 1_000, 0);
    repr.product = Product::Vlp16OldFirmware;
    let mut asm = FrameAssembler::new(DecoderConfig::default()).unwrap();
    asm.push_data(&repr.to_bytes(), 0).unwrap();
    asm.push_data(&repr.to_bytes(), 0).unwrap();
    assert_eq!(asm.stats().products, [0, 2]);
    assert_eq!(asm.stats().points, 2 * 384);
}

proptest! {
    #[test]
    fn mutated_streams_never_panic(
        edits in prop::collection::vec((0usize..1206, any::<u8>()), 0..8),
        starts in prop::collection::vec(0u32..36_000, 1..6),
        dual in any::<bool>(),
        cut_deg in 0f32..359.9,
    ) {
        let config = DecoderConfig { cut_azimuth_rad: cut_deg.to_radians(), ..DecoderConfig::default() };
        let mut asm = FrameAssembler::new(config).unwrap();
        for (k, start) in starts.iter().enumerate() {
            let mut repr = packet(*start, 20, 1_000 + k as u16, k as u32 * 1_327);
            if dual {
                repr.return_mode = ReturnMode::Dual;
                for b in 0..12 {
                    repr.blocks[b].azimuth_raw = ((start + (b as u32 / 2) * 20) % 36_000) as u16;
                }
            }
            let mut bytes = repr.to_bytes();
            for (at, byte) in &edits {
                bytes[*at] = *byte;
            }
            let _ = asm.push_data(&bytes, 0);
            let _ = asm.push_data(&bytes[..k * 100], 0);
        }
        asm.finish();
        let frames = drain(&mut asm);
        let points: usize = frames.iter().map(|f| f.points.len()).sum();
        prop_assert_eq!(points as u64, asm.stats().points);
        for f in &frames {
            for p in &f.points {
                prop_assert!(p.x_m.is_finite() && p.y_m.is_finite() && p.z_m.is_finite());
                prop_assert!(p.time_us.is_finite() && p.ring < 16);
            }
        }
    }
}
