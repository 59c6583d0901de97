//! GenCP over the fake camera's control endpoint: packets, request ids, chunking, pending and
//! stale acks, status codes, and bytes that are not an ack.

use super::fake_u3v::{FakeCamera, FILE, MANIFEST};
use omnitrack_io::capture::control::gencp::*;
use std::time::Duration;

fn client(cam: FakeCamera) -> GenCp<FakeCamera> {
    GenCp::new(cam, Duration::from_millis(50))
}

#[test]
fn reads_and_writes_are_split_to_the_devices_lengths_with_fresh_request_ids() {
    let mut cp = client(FakeCamera::standard());
    cp.set_max_lengths(64, 64);
    let file = cp.read_mem(FILE, 300).unwrap();
    assert_eq!(&file[..], &cp.endpoint_mut().memory[FILE as usize..FILE as usize + 300]);
    // 300 bytes in acks of at most 64 (52 of data each): 6 commands.
    let cmds = cp.endpoint_mut().commands.clone();
    assert_eq!(cmds.len(), 6);
    assert!(cmds.iter().all(|(c, _)| *c == READMEM_CMD));
    let ids: Vec<u16> = cmds.iter().map(|(_, id)| *id).collect();
    assert_eq!(ids, (1..=6).collect::<Vec<u16>>());
    let data: Vec<u8> = (0..40u8).collect();
    cp.write_mem(0x20000, &data).unwrap();
    assert_eq!(&cp.endpoint_mut().memory[0x20000..0x20028], &data[..]);
    // 40 bytes in commands of 64 (44 of data each): one more command.
    assert_eq!(cp.endpoint_mut().commands.last().unwrap(), &(WRITEMEM_CMD, 7));
}

#[test]
fn status_codes_are_errors_naming_the_register_and_the_status() {
    let mut cp = client(FakeCamera::standard());
    let e = cp.read_mem(0x9000_0000, 4).unwrap_err();
    assert_eq!(
        e,
        GenCpError::Status {
            address: 0x9000_0000,
            status: STATUS_INVALID_ADDRESS
        }
    );
    assert_eq!(e.to_string(), "register 0x90000000: status 0x8003 (invalid address)");
    let e = cp.write_mem(MANIFEST, &[1, 2, 3, 4]).unwrap_err();
    assert_eq!(e.to_string(), "register 0x2000: status 0x8004 (write protected)");
    // A read longer than the device's acks, when the client was not told their length.
    let e = cp.read_mem(FILE, 600).unwrap_err();
    assert_eq!(e.to_string(), "register 0x10000: status 0x8002 (invalid parameter)");
}

#[test]
fn pending_and_stale_acks_are_followed_and_dropped() {
    let mut cam = FakeCamera::standard();
    cam.pending = 2;
    cam.stale = true;
    let mut cp = client(cam);
    assert_eq!(cp.read_mem(0x1D0, 8).unwrap(), MANIFEST.to_le_bytes().to_vec());
    assert_eq!(cp.stale_acks(), 1);
    assert_eq!(cp.read_mem(0x1D0, 8).unwrap(), MANIFEST.to_le_bytes().to_vec());
}

#[test]
fn a_silent_or_garbled_device_is_an_error_never_a_panic() {
    let mut cam = FakeCamera::standard();
    cam.silent = true;
    let mut cp = client(cam);
    assert_eq!(
        cp.read_mem(0, 4).unwrap_err().to_string(),
        "no answer from the camera for register 0x0"
    );

    /// An endpoint answering every command with the same bytes.
    struct Echo(Vec<u8>);
    impl ControlEndpoint for Echo {
        fn send(&mut self, _: &[u8], _: Duration) -> Result<(), EndpointError> {
            Ok(())
        }
        fn receive(&mut self, buf: &mut [u8], _: Duration) -> Result<usize, EndpointError> {
            let n = self.0.len().min(buf.len());
            buf[..n].copy_from_slice(&self.0[..n]);
            Ok(n)
        }
    }
    let ack = |magic: u32, status: u16, cmd: u16, len: u16, id: u16, body: &[u8]| {
        let mut a = Vec::new();
        a.extend_from_slice(&magic.to_le_bytes());
        for v in [status, cmd, len, id] {
            a.extend_from_slice(&v.to_le_bytes());
        }
        a.extend_from_slice(body);
        a
    };
    let cases = [
        (
            ack(0x1234_5678, 0, READMEM_ACK, 4, 1, &[0; 4]),
            "register 0x0: an ack without the U3VC prefix",
        ),
        (
            ack(MAGIC, 0, READMEM_ACK, 9, 1, &[0; 4]),
            "register 0x0: an ack shorter than its length field",
        ),
        (
            ack(MAGIC, 0, READMEM_ACK, 2, 1, &[0; 2]),
            "register 0x0: READMEM_ACK of another length than asked",
        ),
        (
            ack(MAGIC, 0, WRITEMEM_ACK, 4, 1, &[0; 4]),
            "register 0x0: an ack of another command",
        ),
        (vec![0x55, 0x33], "register 0x0: an ack shorter than its prefix"),
    ];
    for (bytes, want) in cases {
        let mut cp = GenCp::new(Echo(bytes), Duration::from_millis(20));
        assert_eq!(cp.read_mem(0, 4).unwrap_err().to_string(), want);
    }
    // Random bytes as acks: errors, never a panic or a hang.
    let mut seed = 0x2545_f491_4f6c_dd1du64;
    for _ in 0..500 {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        let len = (seed % 40) as usize;
        let mut bytes: Vec<u8> = (0..len).map(|i| (seed >> (i % 8 * 8)) as u8).collect();
        if len >= 4 && seed % 3 == 0 {
            bytes[..4].copy_from_slice(&MAGIC.to_le_bytes());
        }
        if len >= 8 && bytes[6..8] == PENDING_ACK.to_le_bytes() {
            // An endless PENDING_ACK chain may wait 16 × 65 s by the protocol: not a test.
            bytes[6] = 0;
        }
        let mut cp = GenCp::new(Echo(bytes), Duration::from_millis(1));
        let _ = cp.read_mem(0, 4);
        let _ = cp.write_mem(0, &[1, 2]);
    }
}

#[test]
fn request_ids_wrap_past_zero() {
    let mut cp = client(FakeCamera::standard());
    for _ in 0..65_537 {
        cp.read_mem(0x1CC, 4).unwrap();
    }
    let ids: Vec<u16> = cp.endpoint_mut().commands.iter().map(|(_, id)| *id).collect();
    assert_eq!(&ids[65_533..], &[65_534, 65_535, 1, 2]);
    assert!(!ids.contains(&0), "0 is never a request id");
}
