//! Beat echo degree (BED, Duolando): the beat align score of the
//! follower's motion beats against the LEADER's motion beats instead of the
//! music's, per duet (both clips whole, not cut to a common length, as the
//! authors' `calc_duet_be_score`), then the mean over duets. Beats as in
//! [`super::bas::motion_beats`].

use super::{bas, EvalError};

/// BED of one duet: follower and leader (T, 165) clips.
pub fn duet_score(follower: &[f32], leader: &[f32]) -> Result<f64, EvalError> {
    let fb = bas::motion_beats(follower)?;
    let lb = bas::motion_beats(leader)?;
    bas::align(&lb, &fb, "beat echo degree")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn still_leader_has_no_beats() {
        let still = vec![0.5f32; 40 * 165];
        assert_eq!(
            duet_score(&still, &still),
            Err(EvalError::NoReferenceBeats {
                what: "beat echo degree"
            })
        );
    }
}
