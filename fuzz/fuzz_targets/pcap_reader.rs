//! Any bytes as a pcap/pcapng file: the reader and the UDP unwrapping never panic and never
//! allocate beyond the record limit; what the writer writes reads back.
#![no_main]

use std::net::{Ipv4Addr, SocketAddrV4};

use libfuzzer_sys::fuzz_target;
use vlp16::pcap::{PcapReader, PcapWriter, udp_in_frame};

fuzz_target!(|data: &[u8]| {
    if let Ok(mut reader) = PcapReader::new(data) {
        while let Ok(Some(record)) = reader.next_record() {
            let _ = udp_in_frame(record.link_type, record.data);
        }
    }
    let mut writer = PcapWriter::new(Vec::new()).expect("writing to a Vec");
    let src = SocketAddrV4::new(Ipv4Addr::new(192, 168, 1, 201), 2368);
    let dst = SocketAddrV4::new(Ipv4Addr::BROADCAST, 2368);
    if writer.write_udp(1_000, src, dst, data).is_ok() {
        let bytes = writer.into_inner();
        let mut reader = PcapReader::new(&bytes[..]).expect("own header");
        let record = reader
            .next_record()
            .expect("own record")
            .expect("one record");
        assert_eq!(
            udp_in_frame(record.link_type, record.data)
                .expect("own frame")
                .payload,
            data
        );
    }
});
