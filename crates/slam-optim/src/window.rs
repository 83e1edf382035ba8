//! Local bundle-adjustment window: optimise the last `n` keyframes, fix the older ones that share
//! observations with them (they anchor the gauge), leave the rest out.

use std::collections::BTreeSet;

use crate::values::Key;

/// Split keyframes (oldest first) into the optimised window (the last `n`) and the fixed anchors: older
/// keyframes that observe at least one landmark also seen from the window. `observations[i]` lists the
/// landmark keys seen from `keyframes[i]`. Output key lists are sorted.
pub fn local_window(keyframes: &[Key], observations: &[Vec<Key>], n: usize) -> (Vec<Key>, Vec<Key>) {
    let start = keyframes.len().saturating_sub(n);
    let window: Vec<Key> = keyframes[start..].to_vec();
    let seen: BTreeSet<Key> = observations[start.min(observations.len())..].iter().flatten().copied().collect();
    let anchors: Vec<Key> = keyframes[..start]
        .iter()
        .zip(observations)
        .filter(|(_, obs)| obs.iter().any(|l| seen.contains(l)))
        .map(|(k, _)| *k)
        .collect();
    let mut w = window;
    w.sort();
    (w, anchors)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn window_and_anchors() {
        let kf: Vec<Key> = (0..5).map(Key).collect();
        let obs = vec![vec![Key(10)], vec![Key(11)], vec![Key(12)], vec![Key(11), Key(13)], vec![Key(13)]];
        let (w, a) = local_window(&kf, &obs, 2);
        assert_eq!(w, vec![Key(3), Key(4)]);
        assert_eq!(a, vec![Key(1)]);
        let (w, a) = local_window(&kf, &obs, 10);
        assert_eq!(w.len(), 5);
        assert!(a.is_empty());
    }
}
