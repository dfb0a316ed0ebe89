//! Property tests of the NMEA framer and decoder: a byte stream cut anywhere, into any number of
//! reads, gives the same sentences, counters and fixes as the stream read at once; and no input
//! makes them panic or grow without bound.

use nav::frontend::gps_receiver::{GpsDecoder, GpsStats, LineFramer};
use proptest::prelude::*;

/// A sentence with its checksum.
fn sentence(body: &str) -> String {
    let sum = body.bytes().fold(0u8, |a, b| a ^ b);
    format!("${body}*{sum:02X}\r\n")
}

/// A stream of valid sentences (fixes moving north-east second by second) with some noise
/// between them: garbage bytes, a truncated sentence, a bad checksum, a binary line.
fn stream(n: usize) -> Vec<u8> {
    let mut s = String::from("\u{1}\u{2}garbage before the first sentence");
    for k in 0..n {
        let (sec, min) = (k % 60, 10 + k / 60);
        let lat = format!("2813.{:04}", 900 + k);
        let lon = format!("11259.{:04}", 3700 + k);
        s += &sentence(&format!(
            "GPGGA,12{min:02}{sec:02}.00,{lat},N,{lon},E,1,08,1.1,54.0,M,-20.1,M,,"
        ));
        s += &sentence(&format!(
            "GPRMC,12{min:02}{sec:02}.00,A,{lat},N,{lon},E,19.4,45.0,211126,,,A"
        ));
        if k % 7 == 3 {
            s += "$GPGGA,truncated";
        }
        if k % 11 == 5 {
            s += "$GPGSA,A,3,04,05,,,,,,,,,,,1.5,1.1,1.0*00\r\n";
        }
    }
    let mut b = s.into_bytes();
    b.extend_from_slice(b"$GPTXT,\xff\xfe binary\r\n");
    b
}

fn frame_all(chunks: &[&[u8]]) -> (Vec<String>, GpsStats) {
    let (mut f, mut st, mut out) = (LineFramer::default(), GpsStats::default(), Vec::new());
    for c in chunks {
        f.push(c, &mut st, &mut out);
    }
    (out, st)
}

fn cut<'a>(bytes: &'a [u8], cuts: &[usize]) -> Vec<&'a [u8]> {
    let mut at: Vec<usize> = cuts.iter().map(|c| c % (bytes.len() + 1)).collect();
    at.sort_unstable();
    let mut v = Vec::new();
    let mut from = 0;
    for a in at {
        v.push(&bytes[from..a]);
        from = a;
    }
    v.push(&bytes[from..]);
    v
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2_000))]

    #[test]
    fn any_split_gives_the_same_sentences(n in 1usize..40, cuts in prop::collection::vec(any::<usize>(), 0..60)) {
        let bytes = stream(n);
        let whole = frame_all(&[&bytes]);
        let split = frame_all(&cut(&bytes, &cuts));
        prop_assert_eq!(&whole.0, &split.0);
        prop_assert_eq!(format!("{:?}", whole.1), format!("{:?}", split.1));
        prop_assert!(whole.0.len() >= 2 * n);
    }

    #[test]
    fn any_split_gives_the_same_fixes(n in 1usize..30, cuts in prop::collection::vec(any::<usize>(), 0..40)) {
        let bytes = stream(n);
        let (mut a, mut b) = (GpsDecoder::default(), GpsDecoder::default());
        let (mut fa, mut fb) = (Vec::new(), Vec::new());
        a.push_bytes(&bytes, &mut fa);
        for c in cut(&bytes, &cuts) {
            b.push_bytes(c, &mut fb);
        }
        prop_assert_eq!(format!("{fa:?}"), format!("{fb:?}"));
        prop_assert_eq!(format!("{:?}", a.stats()), format!("{:?}", b.stats()));
        prop_assert!(!fa.is_empty());
    }

    /// Arbitrary bytes: no panic, and every byte is counted.
    #[test]
    fn arbitrary_bytes_are_counted_not_fatal(bytes in prop::collection::vec(any::<u8>(), 0..4096)) {
        let mut d = GpsDecoder::default();
        let mut fixes = Vec::new();
        d.push_bytes(&bytes, &mut fixes);
        prop_assert_eq!(d.stats().bytes, bytes.len() as u64);
    }
}

/// An endless line without a line end is cut, not kept: 8 MB in, one overlong line counted.
#[test]
fn an_endless_line_is_cut_and_counted() {
    let (mut f, mut st, mut out) = (LineFramer::default(), GpsStats::default(), Vec::new());
    f.push(b"$GPGGA,", &mut st, &mut out);
    let chunk = [b'7'; 4096];
    for _ in 0..2_000 {
        f.push(&chunk, &mut st, &mut out);
    }
    f.push(b"\r\n", &mut st, &mut out);
    assert!(out.is_empty());
    assert_eq!(st.overlong_lines, 1);
}
