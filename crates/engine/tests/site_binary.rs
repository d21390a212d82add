//! Binary site files: exact round trips through JSON and binary, and a damaged file (cut short,
//! a flipped byte, a newer version, an invalid entry) is a named error, never a different site.

use waymark_engine::Site;

/// Length of the binary file's leading signature.
const SIGNATURE_LEN: usize = 8;

fn site() -> Site {
    waymark_sim::Office::generate(&waymark_sim::OfficeConfig { seed: 3, ..Default::default() }).site
}

#[test]
fn round_trips_exactly_through_json_and_binary() {
    let site = site();
    let binary = site.to_binary();
    let loaded = Site::from_bytes(&binary).unwrap();
    assert_eq!(loaded.to_json(), site.to_json());
    assert_eq!(loaded.to_binary(), binary);
    let via_json = Site::from_bytes(site.to_json().as_bytes()).unwrap();
    assert_eq!(via_json.to_binary(), binary);
}

#[test]
fn every_truncation_and_every_flipped_byte_is_an_error() {
    let binary = site().to_binary();
    for cut in (0..binary.len()).step_by(97).chain([binary.len() - 1]) {
        let e = Site::from_bytes(&binary[..cut]);
        assert!(e.is_err(), "cut at {cut} loaded");
    }
    for at in (SIGNATURE_LEN..binary.len()).step_by(89) {
        let mut bad = binary.clone();
        bad[at] ^= 0x10;
        assert!(Site::from_bytes(&bad).is_err(), "flipped byte {at} loaded");
    }
}

#[test]
fn names_what_is_wrong() {
    let binary = site().to_binary();
    let message = |bytes: &[u8]| Site::from_bytes(bytes).unwrap_err().to_string();
    assert!(message(&binary[..binary.len() - 10]).contains("checksum"), "{}", message(&binary[..100]));
    assert!(message(&binary[..10]).contains("truncated"));
    let mut newer = binary.clone();
    newer[8] = 2;
    assert!(message(&newer).contains("version 2"));
    // A well-formed file whose entries are invalid fails like the JSON would, with the path.
    let mut wrong = binary.clone();
    let std_column_end = wrong.len() - 4;
    wrong[std_column_end - 2..std_column_end].copy_from_slice(&0u16.to_le_bytes());
    let crc = crc32fast::hash(&wrong[..std_column_end]);
    wrong[std_column_end..].copy_from_slice(&crc.to_le_bytes());
    let m = message(&wrong);
    assert!(m.contains("std_db") && m.contains("fingerprint["), "{m}");
}
