//! Tests of `pickle`.

use super::*;

/// `pickle.dumps({'a': [1, 2], 'b': <the same list>}, protocol=2)`.
const DICT_WITH_MEMO: &[u8] =
    b"\x80\x02}q\x00(X\x01\x00\x00\x00aq\x01]q\x02(K\x01K\x02eX\x01\x00\x00\x00bq\x03h\x02u.";

#[test]
fn protocol_2_dict_with_memo() {
    let data = DICT_WITH_MEMO;
    let p = parse(data).unwrap();
    let a = p.dict_get(p.root, "a").unwrap();
    assert_eq!(p.items(a).unwrap().len(), 2);
    assert_eq!(
        p.dict_get(p.root, "b"),
        Some(a),
        "memo shares, it does not copy"
    );
    assert_eq!(p.consumed, data.len());
}

#[test]
fn reduce_and_build_are_recorded_not_run() {
    // GLOBAL os.system, ('echo',), REDUCE: recorded as a call, never executed.
    let data = b"\x80\x02cos\nsystem\nX\x04\x00\x00\x00echo\x85R}b.";
    let p = parse(data).unwrap();
    match p.get(p.root) {
        Obj::Call {
            callable, state, ..
        } => {
            assert!(p.is_global(*callable, "os", "system"));
            assert!(state.is_some());
        }
        o => panic!("{o:?}"),
    }
}

#[test]
fn every_truncation_is_an_error() {
    let data = DICT_WITH_MEMO;
    for n in 0..data.len() {
        assert!(parse(&data[..n]).is_err(), "prefix {n}");
    }
}

#[test]
fn hostile_inputs_fail_cleanly() {
    for bad in [
        &b"\x80\x09."[..],                       // protocol 9
        b"h\x05.",                               // memo miss
        b"(t(u.",                                // SETITEMS on a tuple
        b"\x8d\xff\xff\xff\xff\xff\xff\xff\xff", // 2^64-byte string
        b"0.",                                   // pop from empty
        b"\xfe",                                 // unknown opcode
    ] {
        assert!(parse(bad).is_err(), "{bad:?}");
    }
    // Random bytes never panic.
    let mut rng = fastrand::Rng::with_seed(7);
    for _ in 0..2000 {
        let n = rng.usize(0..64);
        let v: Vec<u8> = (0..n).map(|_| rng.u8(..)).collect();
        let _ = parse(&v);
    }
}
