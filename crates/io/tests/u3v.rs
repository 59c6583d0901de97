//! The USB3 Vision stream parser on byte streams built here, byte by byte, from the leader and
//! trailer layouts of the standard: good streams in chunks of every size, and truncated, corrupt,
//! mismatched and garbage-ridden ones.

use omnitrack_io::capture::u3v::{PixelFormat, RejectReason, U3vEvent, U3vStream, LEADER_MAGIC, TRAILER_MAGIC};
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};

#[global_allocator]
static ALLOCATOR: omnitrack_testkit::Counting = omnitrack_testkit::Counting;

const W: u32 = 8;
const H: u32 = 6;

/// What the parser reported, owned.
#[derive(Debug, Clone, PartialEq)]
enum Got {
    Frame {
        block_id: u64,
        timestamp: u64,
        rgb: Vec<u8>,
    },
    Rejected(RejectReason, Option<u64>),
}

struct Leader {
    block_id: u64,
    payload_type: u16,
    timestamp: u64,
    pfnc: u32,
    size_x: u32,
    size_y: u32,
    padding_x: u16,
    leader_size: u16,
}

impl Leader {
    fn image(block_id: u64, format: PixelFormat) -> Leader {
        Leader {
            block_id,
            payload_type: 0x0001,
            timestamp: 1_000_000 + block_id * 33_333_333,
            pfnc: format.pfnc(),
            size_x: W,
            size_y: H,
            padding_x: 0,
            leader_size: 52,
        }
    }

    fn bytes(&self) -> Vec<u8> {
        let mut b = Vec::new();
        b.extend_from_slice(&LEADER_MAGIC.to_le_bytes());
        b.extend_from_slice(&[0, 0]); // reserved
        b.extend_from_slice(&self.leader_size.to_le_bytes());
        b.extend_from_slice(&self.block_id.to_le_bytes());
        b.extend_from_slice(&[0, 0]); // reserved
        b.extend_from_slice(&self.payload_type.to_le_bytes());
        b.extend_from_slice(&self.timestamp.to_le_bytes());
        b.extend_from_slice(&self.pfnc.to_le_bytes());
        b.extend_from_slice(&self.size_x.to_le_bytes());
        b.extend_from_slice(&self.size_y.to_le_bytes());
        b.extend_from_slice(&0u32.to_le_bytes()); // offset_x
        b.extend_from_slice(&0u32.to_le_bytes()); // offset_y
        b.extend_from_slice(&self.padding_x.to_le_bytes());
        b.extend_from_slice(&[0, 0]); // reserved
        assert_eq!(b.len(), 52);
        b.resize(self.leader_size.max(16) as usize, 0);
        b
    }
}

fn trailer(block_id: u64, status: u16, valid_payload: u64, size_y: u32) -> Vec<u8> {
    let mut b = Vec::new();
    b.extend_from_slice(&TRAILER_MAGIC.to_le_bytes());
    b.extend_from_slice(&[0, 0]); // reserved
    b.extend_from_slice(&32u16.to_le_bytes()); // trailer_size
    b.extend_from_slice(&block_id.to_le_bytes());
    b.extend_from_slice(&status.to_le_bytes());
    b.extend_from_slice(&[0, 0]); // reserved
    b.extend_from_slice(&valid_payload.to_le_bytes());
    b.extend_from_slice(&size_y.to_le_bytes());
    assert_eq!(b.len(), 32);
    b
}

/// A payload of the format at W × H (with padding), deterministic per block.
fn payload(format: PixelFormat, padding_x: u16, block_id: u64) -> Vec<u8> {
    let line = W as usize * format.bytes_per_pixel() + padding_x as usize;
    (0..line * H as usize)
        .map(|i| ((i as u64 * 7 + block_id * 13) % 251) as u8)
        .collect()
}

/// Leader, payload and trailer of a good block, as the three transfers a camera sends.
fn good_block(block_id: u64, format: PixelFormat, padding_x: u16) -> [Vec<u8>; 3] {
    let mut l = Leader::image(block_id, format);
    l.padding_x = padding_x;
    let p = payload(format, padding_x, block_id);
    let t = trailer(block_id, 0, p.len() as u64, H);
    [l.bytes(), p, t]
}

fn push(parser: &mut U3vStream, transfer: &[u8], got: &mut Vec<Got>) {
    parser.push(transfer, |event| match event {
        U3vEvent::Frame(frame) => {
            let mut rgb = vec![0u8; (W * H * 3) as usize];
            frame.to_rgb(&mut rgb).expect("a delivered frame converts");
            got.push(Got::Frame {
                block_id: frame.info.block_id,
                timestamp: frame.info.timestamp,
                rgb,
            });
        }
        U3vEvent::Rejected { reason, block_id } => got.push(Got::Rejected(reason, block_id)),
    });
}

/// Feeds `bytes` in chunks of random sizes in `1..=max`.
fn push_random(parser: &mut U3vStream, bytes: &[u8], rng: &mut SmallRng, max: usize) -> Vec<Got> {
    let mut got = Vec::new();
    let mut i = 0;
    while i < bytes.len() {
        let n = rng.random_range(1..=max).min(bytes.len() - i);
        push(parser, &bytes[i..i + n], &mut got);
        i += n;
    }
    got
}

fn push_transfers(parser: &mut U3vStream, transfers: &[Vec<u8>]) -> Vec<Got> {
    let mut got = Vec::new();
    for t in transfers {
        push(parser, t, &mut got);
    }
    got
}

fn frame_ids(got: &[Got]) -> Vec<u64> {
    got.iter()
        .filter_map(|g| match g {
            Got::Frame { block_id, .. } => Some(*block_id),
            _ => None,
        })
        .collect()
}

fn rejections(got: &[Got]) -> Vec<(RejectReason, Option<u64>)> {
    got.iter()
        .filter_map(|g| match g {
            Got::Rejected(r, id) => Some((*r, *id)),
            _ => None,
        })
        .collect()
}

/// Five blocks of different formats (one with line padding), concatenated.
fn good_stream() -> (Vec<u8>, Vec<(u64, PixelFormat, u16)>) {
    let blocks = vec![
        (1, PixelFormat::Rgb8, 0),
        (2, PixelFormat::Mono8, 0),
        (3, PixelFormat::BayerRg8, 4),
        (4, PixelFormat::Yuv422_8, 0),
        (5, PixelFormat::Bgr8, 2),
    ];
    let mut bytes = Vec::new();
    for &(id, f, pad) in &blocks {
        for part in good_block(id, f, pad) {
            bytes.extend_from_slice(&part);
        }
    }
    (bytes, blocks)
}

#[test]
fn good_stream_in_chunks_of_any_size_gives_every_frame() {
    let (bytes, blocks) = good_stream();
    let mut reference = None;
    for (seed, max) in [(1u64, 1usize), (2, 3), (3, 17), (4, 64), (5, 700), (6, 5000)] {
        let mut rng = SmallRng::seed_from_u64(seed);
        let mut parser = U3vStream::new(W, H);
        let got = push_random(&mut parser, &bytes, &mut rng, max);
        assert_eq!(frame_ids(&got), vec![1, 2, 3, 4, 5], "seed {seed}, chunks up to {max}");
        assert!(rejections(&got).is_empty(), "{:?}", rejections(&got));
        assert_eq!(parser.stats().frames, 5);
        assert_eq!(parser.stats().total_rejected(), 0);
        assert_eq!(parser.stats().bytes_skipped, 0);
        // Every split gives the same images.
        match &reference {
            None => reference = Some(got),
            Some(r) => assert_eq!(r, &got),
        }
    }
    let got = reference.unwrap();
    // Timestamps come from the leaders.
    if let Got::Frame { timestamp, .. } = &got[1] {
        assert_eq!(*timestamp, 1_000_000 + 2 * 33_333_333);
    }
    // RGB8 is copied as is; Mono8 replicated; BGR8 swapped, line padding skipped.
    let Got::Frame { rgb, .. } = &got[0] else {
        unreachable!()
    };
    assert_eq!(rgb, &payload(PixelFormat::Rgb8, 0, 1));
    let Got::Frame { rgb, .. } = &got[1] else {
        unreachable!()
    };
    let grey = payload(PixelFormat::Mono8, 0, 2);
    assert!(rgb.chunks(3).zip(&grey).all(|(p, &g)| p == [g, g, g]));
    let Got::Frame { rgb, .. } = &got[4] else {
        unreachable!()
    };
    let bgr = payload(PixelFormat::Bgr8, 2, 5);
    let line = (W * 3 + 2) as usize;
    for y in 0..H as usize {
        for x in 0..W as usize {
            let s = &bgr[y * line + x * 3..][..3];
            let o = &rgb[(y * W as usize + x) * 3..][..3];
            assert_eq!(o, [s[2], s[1], s[0]]);
        }
    }
    assert_eq!(blocks.len(), 5);
}

#[test]
fn truncated_payload_with_trailer_in_its_own_transfer_resyncs_at_once() {
    let [l, mut p, _] = good_block(7, PixelFormat::Rgb8, 0);
    p.truncate(p.len() - 10);
    let t = trailer(7, 0, p.len() as u64, H);
    let [l2, p2, t2] = good_block(8, PixelFormat::Rgb8, 0);
    let mut parser = U3vStream::new(W, H);
    let got = push_transfers(&mut parser, &[l, p, t, l2, p2, t2]);
    assert_eq!(rejections(&got), vec![(RejectReason::PayloadSizeMismatch, Some(7))]);
    assert_eq!(frame_ids(&got), vec![8]);
    assert_eq!(parser.stats().rejected(RejectReason::PayloadSizeMismatch), 1);
}

#[test]
fn leader_in_place_of_the_rest_of_a_payload_abandons_the_block() {
    let [l, mut p, _] = good_block(7, PixelFormat::Mono8, 0);
    p.truncate(p.len() / 2);
    let [l2, p2, t2] = good_block(8, PixelFormat::Mono8, 0);
    let mut parser = U3vStream::new(W, H);
    let got = push_transfers(&mut parser, &[l, p, l2, p2, t2]);
    assert_eq!(rejections(&got), vec![(RejectReason::PayloadSizeMismatch, Some(7))]);
    assert_eq!(frame_ids(&got), vec![8]);
}

#[test]
fn truncated_payload_inside_arbitrary_chunks_is_rejected_and_the_stream_recovers() {
    let mut bytes = Vec::new();
    let [l, mut p, _] = good_block(1, PixelFormat::Rgb8, 0);
    p.truncate(p.len() - 20);
    let t = trailer(1, 0, p.len() as u64, H);
    bytes.extend(l);
    bytes.extend(p);
    bytes.extend(t);
    for id in 2..=5 {
        for part in good_block(id, PixelFormat::Rgb8, 0) {
            bytes.extend(part);
        }
    }
    for seed in 0..20 {
        let mut rng = SmallRng::seed_from_u64(seed);
        let mut parser = U3vStream::new(W, H);
        let got = push_random(&mut parser, &bytes, &mut rng, 97);
        let ids = frame_ids(&got);
        assert!(!ids.contains(&1), "the truncated block is never delivered");
        // The block after the broken one may be lost with it; later ones come through.
        assert!(ids.ends_with(&[3, 4, 5]), "seed {seed}: {ids:?}");
        // Noticed where the trailer should be, or at once when a chunk starts with the trailer.
        let first = rejections(&got)[0];
        assert!(
            first == (RejectReason::WrongMagic, Some(1)) || first == (RejectReason::PayloadSizeMismatch, Some(1)),
            "{first:?}"
        );
        assert!(parser.stats().total_rejected() >= 1);
    }
}

#[test]
fn corrupt_leader_magic_is_skipped_and_counted() {
    let [mut l, p, t] = good_block(1, PixelFormat::Rgb8, 0);
    l[3] = b'X'; // U3VX
    let [l2, p2, t2] = good_block(2, PixelFormat::Rgb8, 0);
    let mut parser = U3vStream::new(W, H);
    let got = push_transfers(&mut parser, &[l, p, t, l2, p2, t2]);
    assert_eq!(frame_ids(&got), vec![2]);
    assert_eq!(rejections(&got), vec![(RejectReason::WrongMagic, None)]);
    assert_eq!(parser.stats().rejected(RejectReason::WrongMagic), 1);
    assert!(parser.stats().bytes_skipped > 0);
}

#[test]
fn corrupt_trailer_magic_rejects_the_block() {
    let [l, p, mut t] = good_block(1, PixelFormat::Rgb8, 0);
    t[0] = 0;
    let [l2, p2, t2] = good_block(2, PixelFormat::Rgb8, 0);
    let mut parser = U3vStream::new(W, H);
    let got = push_transfers(&mut parser, &[l, p, t, l2, p2, t2]);
    assert_eq!(frame_ids(&got), vec![2]);
    assert_eq!(rejections(&got), vec![(RejectReason::WrongMagic, Some(1))]);
}

#[test]
fn wrong_block_id_in_trailer_rejects_the_block() {
    let [l, p, _] = good_block(1, PixelFormat::Mono8, 0);
    let t = trailer(99, 0, p.len() as u64, H);
    let [l2, p2, t2] = good_block(2, PixelFormat::Mono8, 0);
    let mut parser = U3vStream::new(W, H);
    let got = push_transfers(&mut parser, &[l, p, t, l2, p2, t2]);
    assert_eq!(rejections(&got), vec![(RejectReason::BlockIdMismatch, Some(1))]);
    assert_eq!(frame_ids(&got), vec![2]);
}

#[test]
fn trailer_status_error_rejects_the_block() {
    let [l, p, _] = good_block(1, PixelFormat::Mono8, 0);
    let t = trailer(1, 0xA100, p.len() as u64, H);
    let [l2, p2, t2] = good_block(2, PixelFormat::Mono8, 0);
    let mut parser = U3vStream::new(W, H);
    let got = push_transfers(&mut parser, &[l, p, t, l2, p2, t2]);
    assert_eq!(rejections(&got), vec![(RejectReason::TrailerStatus, Some(1))]);
    assert_eq!(frame_ids(&got), vec![2]);
    assert_eq!(parser.stats().last_error_status, 0xA100);
}

#[test]
fn valid_payload_size_disagreeing_with_the_leader_rejects_the_block() {
    let [l, p, _] = good_block(1, PixelFormat::Mono8, 0);
    let t = trailer(1, 0, p.len() as u64 - 1, H);
    let mut parser = U3vStream::new(W, H);
    let got = push_transfers(&mut parser, &[l, p, t]);
    assert_eq!(rejections(&got), vec![(RejectReason::PayloadSizeMismatch, Some(1))]);
}

#[test]
fn unsupported_pixel_format_and_payload_type_are_skipped() {
    // Mono10 (16 bits a pixel): the payload is skipped up to the next leader.
    let mut l = Leader::image(1, PixelFormat::Mono8);
    l.pfnc = 0x0110_0003;
    let p: Vec<u8> = vec![0x55; (W * H * 2) as usize]; // full of 'U', no magic
    let t = trailer(1, 0, p.len() as u64, H);
    let mut chunk = Leader::image(2, PixelFormat::Mono8);
    chunk.payload_type = 0x4001;
    let p2 = payload(PixelFormat::Mono8, 0, 2);
    let t2 = trailer(2, 0, p2.len() as u64, H);
    let [l3, p3, t3] = good_block(3, PixelFormat::Mono8, 0);
    let mut parser = U3vStream::new(W, H);
    let got = push_transfers(&mut parser, &[l.bytes(), p, t, chunk.bytes(), p2, t2, l3, p3, t3]);
    assert_eq!(
        rejections(&got),
        vec![
            (RejectReason::UnsupportedPixelFormat, Some(1)),
            (RejectReason::UnsupportedPayloadType, Some(2))
        ]
    );
    assert_eq!(frame_ids(&got), vec![3]);
    assert_eq!(PixelFormat::from_pfnc(0x0110_0003), None);
}

#[test]
fn image_size_other_than_the_sensors_is_rejected() {
    let mut l = Leader::image(1, PixelFormat::Mono8);
    l.size_x = W * 2;
    let p = vec![1u8; (W * 2 * H) as usize];
    let t = trailer(1, 0, p.len() as u64, H);
    // A trailer whose size_y disagrees with the leader.
    let [l2, p2, _] = good_block(2, PixelFormat::Mono8, 0);
    let t2 = trailer(2, 0, p2.len() as u64, H - 1);
    let [l3, p3, t3] = good_block(3, PixelFormat::Mono8, 0);
    let mut parser = U3vStream::new(W, H);
    let got = push_transfers(&mut parser, &[l.bytes(), p, t, l2, p2, t2, l3, p3, t3]);
    assert_eq!(
        rejections(&got),
        vec![
            (RejectReason::SizeMismatch, Some(1)),
            (RejectReason::SizeMismatch, Some(2))
        ]
    );
    assert_eq!(frame_ids(&got), vec![3]);
}

#[test]
fn leader_size_field_out_of_range_is_a_bad_header() {
    let mut l = Leader::image(1, PixelFormat::Mono8);
    l.leader_size = 20;
    let [l2, p2, t2] = good_block(2, PixelFormat::Mono8, 0);
    let mut parser = U3vStream::new(W, H);
    let got = push_transfers(&mut parser, &[l.bytes(), l2, p2, t2]);
    assert_eq!(rejections(&got), vec![(RejectReason::BadHeader, Some(1))]);
    assert_eq!(frame_ids(&got), vec![2]);
}

#[test]
fn garbage_before_and_between_blocks_is_skipped_and_counted_once_per_run() {
    // Garbage with near-misses: 'U', "U3", "U3V", a trailer magic where a leader is expected.
    let mut garbage1 = b"\x00\x01U\x02U3\x03U3V\x04U3VTxyzzyU".to_vec();
    garbage1.extend((0..300u32).map(|i| (i * 31 % 200) as u8 + 1).filter(|&b| b != b'U'));
    let garbage2 = vec![0xAAu8; 1000];
    let mut bytes = garbage1.clone();
    for part in good_block(1, PixelFormat::Rgb8, 0) {
        bytes.extend(part);
    }
    bytes.extend(&garbage2);
    for part in good_block(2, PixelFormat::BayerGb8, 0) {
        bytes.extend(part);
    }
    for (seed, max) in [(1u64, 1usize), (2, 7), (3, 100), (4, 4000)] {
        let mut rng = SmallRng::seed_from_u64(seed);
        let mut parser = U3vStream::new(W, H);
        let got = push_random(&mut parser, &bytes, &mut rng, max);
        assert_eq!(frame_ids(&got), vec![1, 2], "seed {seed}");
        assert_eq!(
            rejections(&got),
            vec![(RejectReason::WrongMagic, None), (RejectReason::WrongMagic, None)]
        );
        assert_eq!(parser.stats().bytes_skipped, (garbage1.len() + garbage2.len()) as u64);
    }
}

#[test]
fn random_bytes_and_mutated_streams_never_panic() {
    let mut rng = SmallRng::seed_from_u64(42);
    let mut parser = U3vStream::new(W, H);
    let noise: Vec<u8> = (0..100_000).map(|_| rng.random()).collect();
    let _ = push_random(&mut parser, &noise, &mut rng, 300);
    let (good, _) = good_stream();
    for _ in 0..200 {
        let mut bytes = good.clone();
        for _ in 0..rng.random_range(1..10) {
            let i = rng.random_range(0..bytes.len());
            bytes[i] = rng.random();
        }
        if rng.random_bool(0.3) {
            let cut = rng.random_range(0..bytes.len());
            bytes.truncate(cut);
        }
        let mut parser = U3vStream::new(W, H);
        let _ = push_random(&mut parser, &bytes, &mut rng, 200);
        // After a reset (what a source does when it reopens a camera) the parser works again.
        parser.reset();
        let mut got = Vec::new();
        for part in good_block(77, PixelFormat::Mono8, 0) {
            push(&mut parser, &part, &mut got);
        }
        assert_eq!(frame_ids(&got), vec![77]);
    }
}

#[test]
fn pixel_format_codes_are_the_pfnc_ones() {
    assert_eq!(PixelFormat::from_pfnc(0x0108_0001), Some(PixelFormat::Mono8));
    assert_eq!(PixelFormat::from_pfnc(0x0218_0014), Some(PixelFormat::Rgb8));
    assert_eq!(PixelFormat::from_pfnc(0x0108_0009), Some(PixelFormat::BayerRg8));
    assert_eq!(PixelFormat::from_pfnc(0x0108_0008), Some(PixelFormat::BayerGr8));
    assert_eq!(PixelFormat::from_pfnc(0x0108_000B), Some(PixelFormat::BayerBg8));
    assert_eq!(PixelFormat::from_pfnc(0x0108_000A), Some(PixelFormat::BayerGb8));
    assert_eq!(PixelFormat::from_pfnc(0x0210_0032), Some(PixelFormat::Yuv422_8));
    assert_eq!(PixelFormat::from_pfnc(0x0210_003B), Some(PixelFormat::YCbCr422_8));
    assert_eq!(LEADER_MAGIC.to_le_bytes(), *b"U3VL");
    assert_eq!(TRAILER_MAGIC.to_le_bytes(), *b"U3VT");
}

#[test]
fn parsing_and_converting_allocate_nothing() {
    let (bytes, _) = good_stream();
    let mut garbage = vec![0x11u8; 100];
    garbage.extend_from_slice(&bytes);
    let mut parser = U3vStream::new(W, H);
    let mut rgb = vec![0u8; (W * H * 3) as usize];
    omnitrack_testkit::assert_counter_works();
    let mut frames = 0;
    let ((), allocated) = omnitrack_testkit::allocations_in(|| {
        for round in 0..50 {
            // Chunks of a few sizes, without a random generator (nothing else runs while counting).
            let size = [1usize, 13, 512, 4096][round % 4];
            for chunk in garbage.chunks(size) {
                parser.push(chunk, |event| {
                    if let U3vEvent::Frame(frame) = event {
                        frame.to_rgb(&mut rgb).unwrap();
                        frames += 1;
                    }
                });
            }
        }
    });
    assert_eq!(frames, 250);
    assert_eq!(allocated, 0);
}
