//! Session files: a session that loads is valid (its trackers build, its values are in the
//! widgets' ranges), saves, and loads back the same.
#![no_main]

mod scratch;

use libfuzzer_sys::fuzz_target;
use regtrack::session::State;

fuzz_target!(|data: &[u8]| {
    let p = scratch::scratch("session").join("s.toml");
    std::fs::write(&p, data).unwrap();
    let Ok(state) = State::load(&p) else {
        return;
    };
    state.save(&p).expect("a loaded session saves");
    let again = State::load(&p).expect("a saved session loads");
    assert_eq!(state, again);
});
