//! A recording from an end-to-end run read with the field's own MCAP reader (Python `mcap`):
//! its summary's counts match what is read, the Foxglove topics carry Foxglove's schemas by
//! name, every JSON message (every 50th of the 2 kHz IMU samples) is validated against its
//! channel's JSON schema (Python `jsonschema`), and the raw channels (CAN frames, GPS bytes)
//! decode by their `ros2msg` schemas (`mcap-ros2-support`; the received frames of the first 2 s), each
//! stamp equal to its log time; all installed by `./run-tests`. Ignored by a plain `cargo test`: `./run-tests` runs it after the
//! end-to-end tests have left the campus loop's `nav.mcap` in `target/e2e-reports/`.

const CHECK: &str = r#"
import json, sys
from collections import Counter
from jsonschema import Draft202012Validator
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
counts, bad, schemas, checked, names, logged = Counter(), [], {}, 0, {}, {}
decoders, cdr_checked, serial = {}, Counter(), bytearray()

def cdr(schema, channel, message, k):
    """A CDR message decoded by its ros2msg schema (mcap-ros2-support) and checked."""
    at = f"{channel.topic} #{k}"
    if schema is None or schema.encoding != "ros2msg":
        bad.append(f"{at}: no ros2msg schema")
        return
    dec = decoders.get(schema.id)
    if dec is None:
        dec = decoders[schema.id] = DecoderFactory().decoder_for("cdr", schema)
    m = dec(message.data)
    cdr_checked[channel.topic] += 1
    names[channel.topic] = schema.name
    if m.stamp.sec * 10**9 + m.stamp.nanosec != message.log_time:
        bad.append(f"{at}: stamp {m.stamp} is not its log time {message.log_time}")
    if schema.name == "rlg_hil/msg/CanFrame":
        data = bytes(m.data)
        if not (0 <= m.id <= 0x7FF and not m.extended and not m.remote and m.dlc <= 8
                and len(data) == 8 and not any(data[m.dlc:])):
            bad.append(f"{at}: not a classic frame of the bus: {m}")
    elif schema.name == "rlg_hil/msg/SerialBytes":
        serial.extend(bytes(m.data))
    else:
        bad.append(f"{at}: unknown schema {schema.name}")

with open(sys.argv[1], "rb") as f:
    reader = make_reader(f)
    summary = reader.get_summary()
    # message counts from the summary section; every JSON message is read and validated but
    # the 2 kHz IMU samples, of which every 50th is (pure Python takes a while)
    for cid, n in summary.statistics.channel_message_counts.items():
        counts[summary.channels[cid].topic] += n
    json_topics = [c.topic for c in summary.channels.values() if c.message_encoding == "json"]
    # the CDR channels (raw CAN frames, serial bytes) decoded by their ros2msg schemas: every
    # message but the 4 kHz received frames, of which the first 2 s of log time are (a pass over all of
    # them alone takes 7 s)
    cdr_topics = [c.topic for c in summary.channels.values() if c.message_encoding == "cdr"]
    busy = [t for t in cdr_topics if t in ("/can/raw", "/bench/can/tx")]
    read = json_topics + [t for t in cdr_topics if t not in busy]
    seen = Counter()
    for schema, channel, message in reader.iter_messages(topics=read):
        seen[channel.topic] += 1
        if channel.message_encoding == "cdr":
            cdr(schema, channel, message, seen[channel.topic])
            continue
        if channel.topic == "/imu/sample" and seen[channel.topic] % 50 != 1:
            continue
        checked += 1
        names[channel.topic] = schema.name if schema else None
        lo, hi = logged.get(channel.topic, (message.log_time, message.log_time))
        logged[channel.topic] = (min(lo, message.log_time), max(hi, message.log_time))
        if schema is None or schema.encoding != "jsonschema":
            bad.append(f"{channel.topic}: no JSON schema")
            continue
        v = schemas.get(schema.id)
        if v is None:
            s = json.loads(schema.data)
            Draft202012Validator.check_schema(s)
            v = schemas[schema.id] = Draft202012Validator(s)
        for e in v.iter_errors(json.loads(message.data)):
            if len(bad) < 20:
                bad.append(f"{channel.topic} #{seen[channel.topic]}: {e.message}")
    if busy:
        t0 = summary.statistics.message_start_time
        for k, (schema, channel, message) in enumerate(
                reader.iter_messages(topics=busy, end_time=t0 + 2 * 10**9)):
            cdr(schema, channel, message, k + 1)
if seen != Counter({t: counts[t] for t in read if counts[t]}):
    bad.append(f"read {dict(seen)}, the summary counts {dict(counts)}")
print(json.dumps({"counts": counts, "bad": bad[:20], "schemas": len(schemas), "checked": checked,
                  "schema_names": names, "log_range": logged, "cdr_checked": cdr_checked,
                  "nmea_sentences": serial.count(b"$G"),
                  "chunks": len(summary.chunk_indexes) if summary else 0}))
"#;

/// The checker's findings on one recording; no message off its schema.
fn check(name: &str) -> serde_json::Value {
    let mcap = e2e::reports_dir().join("campus-loop").join(name);
    assert!(
        mcap.is_file(),
        "{} is missing (the campus loop e2e test leaves it)",
        mcap.display()
    );
    let out = e2e::python(CHECK, &[&mcap], &format!("the Python reader on {name}"));
    let r: serde_json::Value = serde_json::from_slice(&out).expect("the checker's JSON");
    eprintln!("{name}: {r}");
    assert_eq!(
        r["bad"],
        serde_json::json!([]),
        "{name}: messages off their schema"
    );
    assert!(
        r["chunks"].as_u64().unwrap() > 0,
        "{name}: the summary section indexes its chunks: {r}"
    );
    r
}

#[test]
#[ignore = "needs an end-to-end run's recording: run ./run-tests"]
fn a_run_recording_reads_in_python_mcap_and_every_json_message_follows_its_schema() {
    let r = check("nav.mcap");
    let c = &r["counts"];
    for topic in [
        "/can/raw",
        "/can/tx",
        "/imu/sample",
        "/nav/event",
        "/nav/solution",
        "/gps/fix",
        "/nav/summary",
        "/nav/location",
        "/gps/location",
        "/nav/pose",
        "/nav/log",
    ] {
        assert!(c[topic].as_u64().unwrap_or(0) > 0, "no {topic}: {c}");
    }
    // Foxglove's well-known schemas, by the names its viewers know them by
    for (topic, name) in [
        ("/nav/location", "foxglove.LocationFix"),
        ("/gps/location", "foxglove.LocationFix"),
        ("/nav/pose", "foxglove.PoseInFrame"),
        ("/nav/log", "foxglove.Log"),
    ] {
        assert_eq!(r["schema_names"][topic], name, "{r}");
    }
    assert!(r["schemas"].as_u64().unwrap() >= 5, "{r}");
    // the raw traffic under its published ros2msg schemas
    for (topic, name) in [
        ("/can/raw", "rlg_hil/msg/CanFrame"),
        ("/can/tx", "rlg_hil/msg/CanFrame"),
        ("/gps/raw", "rlg_hil/msg/SerialBytes"),
    ] {
        assert_eq!(r["schema_names"][topic], name, "{r}");
        assert!(r["cdr_checked"][topic].as_u64().unwrap_or(0) > 0, "{r}");
    }
    // the campus loop's GPS: at 1 Hz, several sentences an epoch, for minutes
    assert!(r["nmea_sentences"].as_u64().unwrap() > 100, "{r}");

    // the bench's truth beside it, on the wall clock nav logged the same instants at
    let t = check("truth.mcap");
    assert_eq!(t["schema_names"]["/truth/location"], "foxglove.LocationFix");
    assert!(
        t["counts"]["/truth/state"].as_u64().unwrap_or(0) > 100,
        "{t}"
    );
    // the turntable's truth through the drill, and the faults injected while driving (the
    // receiver's port drop, multipath burst and outage: a start and an end each), under their
    // schemas
    assert_eq!(
        t["schema_names"]["/truth/turntable"],
        "rlg-hil/bench/turntable-truth"
    );
    assert!(
        t["counts"]["/truth/turntable"].as_u64().unwrap_or(0) > 100,
        "{t}"
    );
    assert_eq!(t["schema_names"]["/bench/faults"], "foxglove.Log");
    assert_eq!(t["counts"]["/bench/faults"], 6, "{t}");
    let range = |v: &serde_json::Value, topic: &str| -> (f64, f64) {
        let a = &v["log_range"][topic];
        (a[0].as_f64().unwrap(), a[1].as_f64().unwrap())
    };
    let (n0, n1) = range(&r, "/nav/location");
    let (t0, t1) = range(&t, "/truth/location");
    // truth spans the whole run, nav's solution the part it navigated: within it, on one clock
    assert!(
        t0 <= n0 + 1e9 && t1 >= n1 - 1e9,
        "truth's log times {t0}..{t1} do not cover nav's {n0}..{n1}"
    );
    assert!(
        t1 - t0 < 2.0 * (n1 - n0) + 120e9,
        "truth {t0}..{t1}, nav {n0}..{n1}"
    );
}
