//! Frame lengths on the wire against references not written here.

use can_transport::CanFrame;
use can_transport::wire::bits::{self, exact, exact_fields, worst_case_bits};

/// can-utils' canframelen.c (CFL_EXACT) on 794 frames: CANopen frames, bit-pattern extremes
/// and random frames (tests/data/canframelen-exact.txt says how it was made).
#[test]
fn exact_lengths_agree_with_can_utils_canframelen() {
    let text = include_str!("data/canframelen-exact.txt");
    let mut n = 0;
    for (ln, line) in text.lines().enumerate() {
        if line.starts_with('#') || line.trim().is_empty() {
            continue;
        }
        let f: Vec<&str> = line.split_whitespace().collect();
        let id = u32::from_str_radix(f[0], 16).unwrap();
        let ext = f[1] == "1";
        let rtr = f[2] == "1";
        let dlc: u8 = f[3].parse().unwrap();
        let (hex, want) = if f.len() == 6 {
            (f[4], f[5])
        } else {
            ("", f[4])
        };
        let data: Vec<u8> = (0..hex.len() / 2)
            .map(|i| u8::from_str_radix(&hex[2 * i..2 * i + 2], 16).unwrap())
            .collect();
        let frame = if rtr {
            CanFrame::remote(id, ext, dlc).unwrap()
        } else {
            CanFrame::with_flags(id, ext, false, &data).unwrap()
        };
        let want: u32 = want.parse().unwrap();
        assert_eq!(exact(&frame).total(), want, "line {}: {line}", ln + 1);
        n += 1;
    }
    assert!(n > 790, "only {n} frames read");
}

/// CRC-15/CAN of the CRC catalogue (reveng, "CRC-15/CAN": width 15, poly 0x4599, init 0,
/// check 0x059E over the ASCII "123456789").
#[test]
fn crc15_matches_the_crc_catalogue_check_value() {
    assert_eq!(bits::crc15_bytes(b"123456789"), 0x059E);
}

/// A frame captured from a car's OBD-II port with its CRC as it was on the wire
/// (github.com/dominic-meads/CAN_2.0, README "BITSTREAM FOR CAR": identifier 0x0C1, DLC 8,
/// data 40 01 08 75 00 00 00 00, CRC 101101101000000).
#[test]
fn crc_of_a_frame_captured_on_a_car_bus() {
    let f = CanFrame::new(0x0C1, &[0x40, 0x01, 0x08, 0x75, 0, 0, 0, 0]).unwrap();
    assert_eq!(exact(&f).crc, 0b101101101000000);
}

/// The worst case against the two published forms of Davis et al. (2007), eq. (2): can-utils'
/// `canframelen.h` comment "(34 + 8n - 1)/4 + 34 + 8n + 13 for SFF frames, (54 + 8n - 1)/4 +
/// 54 + 8n + 13 for EFF frames", and the Linux kernel's `include/linux/can/length.h`
/// (since 6.3): `can_frame_bits(false, is_eff, true, true, n)` =
/// `can_bitstuffing_len(header + 8n + CAN_FRAME_CRC_FIELD_BITS) + CAN_FRAME_FOOTER_BITS +
/// CAN_INTERMISSION_BITS` with header 19 / 39, CRC field 16, footer 9, intermission 3 and
/// `can_bitstuffing_len(l) = l + (l - 1) / 4`.
#[test]
fn worst_case_matches_davis_as_can_utils_and_the_kernel_state_it() {
    let kernel_stuffed = |l: u32| l + (l - 1) / 4;
    for n in 0..=8u8 {
        let n32 = u32::from(n);
        let can_utils_sff = (34 + 8 * n32 - 1) / 4 + 34 + 8 * n32 + 13;
        let can_utils_eff = (54 + 8 * n32 - 1) / 4 + 54 + 8 * n32 + 13;
        let kernel_sff = kernel_stuffed(19 + 8 * n32 + 16) + 9 + 3;
        let kernel_eff = kernel_stuffed(39 + 8 * n32 + 16) + 9 + 3;
        assert_eq!(worst_case_bits(false, n), can_utils_sff, "n = {n}");
        assert_eq!(worst_case_bits(true, n), can_utils_eff, "n = {n}");
        assert_eq!(worst_case_bits(false, n), kernel_sff, "n = {n}");
        assert_eq!(worst_case_bits(true, n), kernel_eff, "n = {n}");
    }
    // The figures every CAN text quotes: 135 and 160 bits for 8 data bytes.
    assert_eq!(worst_case_bits(false, 8), 135);
    assert_eq!(worst_case_bits(true, 8), 160);
    // Without stuffing: 47 / 67 + 8n (kernel: CAN_FRAME_LEN_MAX = 17 bytes = ⌈131 / 8⌉).
    assert_eq!(bits::unstuffed_bits(true, 8).div_ceil(8), 17);
}

/// CAN FD against the kernel's `can_frame_bits(true, is_eff, true, true, n)`: header 22 / 41,
/// CRC-17 field 28 (≤ 16 bytes) or CRC-21 field 33, footer 9, intermission 3.
#[test]
fn fd_worst_case_matches_the_kernel() {
    let kernel_stuffed = |l: u32| l + (l - 1) / 4;
    for n in [0u8, 1, 8, 12, 16, 20, 24, 32, 48, 64] {
        for ext in [false, true] {
            let header = if ext { 41 } else { 22 };
            let crc = if n <= 16 { 28 } else { 33 };
            let want = kernel_stuffed(header + 8 * u32::from(n)) + crc + 9 + 3;
            assert_eq!(
                bits::fd_worst_case_bits(ext, n),
                want,
                "n = {n}, ext = {ext}"
            );
            let (nominal, data) = bits::fd_worst_case_split(ext, n);
            assert_eq!(nominal + data, want);
        }
    }
    // 64 bytes, 11-bit id, 1 Mbit/s arbitration and 5 Mbit/s data: the nominal part is
    // SOF..BRS with its worst stuffing (17 + 4), CRC delimiter, ACK, EOF, intermission.
    let (nominal, data) = bits::fd_worst_case_split(false, 64);
    assert_eq!(nominal, 21 + 1 + 9 + 3);
    assert_eq!(
        bits::fd_worst_case_ns(false, 64, 1_000_000, 5_000_000),
        u64::from(nominal) * 1000 + u64::from(data) * 200
    );
}

proptest::proptest! {
    /// Every frame lies between its unstuffed length and Davis's bound.
    #[test]
    fn exact_lies_between_unstuffed_and_the_worst_case(
        id in 0u32..0x2000_0000, ext: bool, rtr: bool, len in 0u8..=8, data: [u8; 8]
    ) {
        let id = if ext { id } else { id & 0x7FF };
        let f = exact_fields(id, ext, rtr, len, &data);
        let n = if rtr { 0 } else { len };
        proptest::prop_assert!(f.total() >= bits::unstuffed_bits(ext, n));
        proptest::prop_assert!(f.total() <= worst_case_bits(ext, n));
        proptest::prop_assert_eq!(f.unstuffed + bits::TRAILER_BITS + bits::INTERMISSION_BITS,
            bits::unstuffed_bits(ext, n));
    }
}

/// A remote frame carries its DLC but no data: its length does not depend on the DLC's
/// payload (can-utils' CFL_EXACT counts data bytes for remote frames too, so this is ours).
#[test]
fn remote_frames_have_no_data_field() {
    let r = exact(&CanFrame::remote(0x701, false, 8).unwrap());
    assert_eq!(r.unstuffed, 19 + 15);
    let r0 = exact(&CanFrame::remote(0x701, false, 0).unwrap());
    assert_eq!(r0.unstuffed, 19 + 15);
}
