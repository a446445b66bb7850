//! `.duo` decoding on structured inputs (`duolando_gen::duo::DuoInput`):
//! semantic edits of the valid tiny2 file (config varints, tensor-table
//! entries, then bytes aimed at a region), or raw bytes. The invariant is
//! `check_duo`'s: never a panic; an accepted file has every listed tensor
//! readable with its listed dtype and dims, and binding answers.
#![no_main]

use std::sync::OnceLock;

use arbitrary::{Arbitrary, Unstructured};
use duolando_gen::duo::{build, check_duo, split, DuoInput, Parts};
use duolando_gen::fixture::tiny2_duo_bytes;
use libfuzzer_sys::fuzz_target;

fn base() -> &'static Parts {
    static P: OnceLock<Parts> = OnceLock::new();
    P.get_or_init(|| split(tiny2_duo_bytes()))
}

fuzz_target!(|data: &[u8]| {
    let mut u = Unstructured::new(data);
    let Ok(input) = DuoInput::arbitrary(&mut u) else { return };
    let bytes = build(&input, base());
    let _ = check_duo(&bytes);
});
