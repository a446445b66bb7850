//! Rule 14 of docs/FORMAT.md: the table holds exactly the tensors that
//! `schema::for_each_tensor` lists for the file's config, with its shapes
//! (a ConvTranspose1d weight in either order: `TensorSpec::accepts`).

use super::{DuoFile, FormatError, Shape};
use crate::family::FamilyConfig;
use crate::nn::names::{SchemaError, TensorSpec};

impl From<SchemaError> for FormatError {
    fn from(e: SchemaError) -> FormatError {
        FormatError::Schema(e)
    }
}

/// Every schema tensor present with the schema shape (or a ConvTranspose1d
/// weight's GEMM-order shape); nothing else present.
pub(super) fn check(file: &DuoFile<'_>) -> Result<(), FormatError> {
    let mut schema_index: u32 = 0;
    file.config()
        .for_each_tensor::<FormatError>(&mut |spec: &TensorSpec| {
            let (index, e) = file
                .find(spec.name.as_str())
                .ok_or(FormatError::MissingTensor { schema_index })?;
            if !spec.accepts(e.dims()) {
                return Err(FormatError::ShapeMismatch {
                    index,
                    expected: Shape {
                        rank: spec.rank,
                        dims: spec.shape,
                    },
                    found: e.shape(),
                });
            }
            schema_index += 1;
            Ok(())
        })?;
    // Table names are unique (rule 11.8) and each schema name matched one,
    // so a longer table holds at least one tensor the schema lacks.
    if file.len() > schema_index as usize {
        for (index, e) in file.tensors().enumerate() {
            if !in_schema(file, e.name) {
                return Err(FormatError::UnknownTensor {
                    index: index as u32,
                });
            }
        }
    }
    Ok(())
}

/// Whether `name` is one of the schema's tensors (error path only).
fn in_schema(file: &DuoFile<'_>, name: &str) -> bool {
    #[derive(Debug)]
    enum Stop {
        Found,
        Schema,
    }
    impl From<SchemaError> for Stop {
        fn from(_: SchemaError) -> Stop {
            Stop::Schema
        }
    }
    let r = file
        .config()
        .for_each_tensor::<Stop>(&mut |spec: &TensorSpec| {
            if spec.name.as_str() == name {
                Err(Stop::Found)
            } else {
                Ok(())
            }
        });
    matches!(r, Err(Stop::Found))
}

/// The name and shape of schema tensor `schema_index` for `cfg` (for
/// messages about `MissingTensor`).
// The spec travels by value through the visitor's error channel once, on
// an error path; boxing it would need alloc.
#[allow(clippy::result_large_err)]
pub fn schema_tensor(cfg: &FamilyConfig, schema_index: u32) -> Option<TensorSpec> {
    enum Stop {
        Found(TensorSpec),
        Schema,
    }
    impl From<SchemaError> for Stop {
        fn from(_: SchemaError) -> Stop {
            Stop::Schema
        }
    }
    let mut i = 0u32;
    let r = cfg.for_each_tensor::<Stop>(&mut |spec: &TensorSpec| {
        if i == schema_index {
            return Err(Stop::Found(spec.clone()));
        }
        i += 1;
        Ok(())
    });
    match r {
        Err(Stop::Found(spec)) => Some(spec),
        _ => None,
    }
}
