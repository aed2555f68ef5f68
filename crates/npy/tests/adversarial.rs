//! Hostile `.npy` headers: refused with a message, never an allocation of what they declare.

#[test]
fn npy_zero_width_strings_with_a_huge_shape_are_refused() {
    let header = "{'descr': '<U0', 'fortran_order': False, 'shape': (1000000000000000,), }\n";
    let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
    bytes.extend_from_slice(&(header.len() as u16).to_le_bytes());
    bytes.extend_from_slice(header.as_bytes());
    let e = npy::parse_npy(&bytes).expect_err("refused");
    assert!(e.contains("zero-width"), "{e}");
}
