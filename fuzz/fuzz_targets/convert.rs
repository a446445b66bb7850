//! The converter (`duolando::convert::convert_bytes`) on structured inputs
//! (`duolando_gen::convert::ConvertInput`): edits of the tiny2 sources
//! (YAML lines, safetensors JSON headers, bytes by region) or raw YAML and
//! safetensors bytes. The invariant is `check_convert`'s: never a panic; a
//! named `ConvertError`, or a `.duo` that parses and binds.
#![no_main]

use arbitrary::{Arbitrary, Unstructured};
use duolando_gen::convert::{build, check_convert, ConvertInput};
use duolando_gen::fixture::tiny2_convert_sources;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let mut u = Unstructured::new(data);
    let Ok(input) = ConvertInput::arbitrary(&mut u) else { return };
    let built = build(&input, tiny2_convert_sources());
    let _ = check_convert(&built);
});
