//! What every text reader shares: bytes become text without a leading byte-order mark, or an
//! error naming the file and the first line that is not UTF-8; and the natural order of names
//! (numbers by value) is a total order.
#![no_main]

use libfuzzer_sys::fuzz_target;
use regtrack::dataset::natural_cmp;
use std::cmp::Ordering;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    let path = Path::new("t.txt");
    let body = data.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(data);
    match regtrack::files::text_of(path, data.to_vec()) {
        Ok(text) => assert_eq!(text.as_bytes(), body),
        Err(e) => {
            let valid = std::str::from_utf8(body).unwrap_err().valid_up_to();
            let line = body[..valid].iter().filter(|&&b| b == b'\n').count() + 1;
            let e = e.to_string();
            assert!(e.starts_with("t.txt") && e.contains(&format!(":{line}")), "{e}");
        }
    }
    // Three names from the bytes: the order is reflexive, antisymmetric and transitive.
    let text = String::from_utf8_lossy(data);
    let names: Vec<&str> = text.splitn(3, '|').collect();
    for a in &names {
        assert_eq!(natural_cmp(a, a), Ordering::Equal);
        for b in &names {
            assert_eq!(natural_cmp(a, b), natural_cmp(b, a).reverse(), "{a:?} {b:?}");
            for c in &names {
                if natural_cmp(a, b) != Ordering::Greater && natural_cmp(b, c) != Ordering::Greater {
                    assert_ne!(natural_cmp(a, c), Ordering::Greater, "{a:?} {b:?} {c:?}");
                }
            }
        }
    }
});
