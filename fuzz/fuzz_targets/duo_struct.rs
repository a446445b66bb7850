//! `.duo` decoding on structured inputs (`duolando_gen::duo::DuoInput`):
//! semantic edits of the valid tiny2 file (Duolando, format version 1) and
//! of the btiny file (Bailando, version 2), each input on both (family
//! tags, config varints, tensor-table
//! entries, then bytes aimed at a region), weights overwritten with NaN,
//! infinities and finite edge values, or raw bytes. The invariant is
//! `check_input`'s: never a panic; an accepted file has every listed tensor
//! readable with its listed dtype and dims and only finite weights, and
//! binding answers; a file with a NaN or infinite weight is refused naming
//! the first one (tensor, element).
#![no_main]

use std::sync::OnceLock;

use arbitrary::{Arbitrary, Unstructured};
use duolando_gen::duo::{check_input, split, DuoInput, Parts};
use duolando_gen::fixture::{btiny_duo_bytes, tiny2_duo_bytes, transflower_duo_bytes};
use libfuzzer_sys::fuzz_target;

fn bases() -> &'static [Parts; 3] {
    static P: OnceLock<[Parts; 3]> = OnceLock::new();
    P.get_or_init(|| [split(tiny2_duo_bytes()), split(btiny_duo_bytes()), split(transflower_duo_bytes())])
}

fuzz_target!(|data: &[u8]| {
    let mut u = Unstructured::new(data);
    let Ok(input) = DuoInput::arbitrary(&mut u) else { return };
    for base in bases() {
        let _ = check_input(&input, base);
    }
});
