//! "Did you mean …": the known names nearest to a misspelt one.

/// Edit distance (insertions, deletions, substitutions, adjacent swaps), case-insensitive.
pub fn distance(a: &str, b: &str) -> usize {
    let a: Vec<u8> = a.bytes().map(|c| c.to_ascii_lowercase()).collect();
    let b: Vec<u8> = b.bytes().map(|c| c.to_ascii_lowercase()).collect();
    let w = b.len() + 1;
    let mut d = vec![0usize; (a.len() + 1) * w];
    for (j, x) in d.iter_mut().enumerate().take(w) {
        *x = j;
    }
    for i in 1..=a.len() {
        d[i * w] = i;
        for j in 1..=b.len() {
            let cost = usize::from(a[i - 1] != b[j - 1]);
            let mut v = (d[(i - 1) * w + j] + 1)
                .min(d[i * w + j - 1] + 1)
                .min(d[(i - 1) * w + j - 1] + cost);
            if i > 1 && j > 1 && a[i - 1] == b[j - 2] && a[i - 2] == b[j - 1] {
                v = v.min(d[(i - 2) * w + j - 2] + 1);
            }
            d[i * w + j] = v;
        }
    }
    d[a.len() * w + b.len()]
}

/// Up to `n` candidates nearest to `word`, nearest first: those within a third of the word's
/// length in edits, and those that contain it (or are contained in it).
pub fn nearest<'a>(
    word: &str,
    candidates: impl IntoIterator<Item = &'a str>,
    n: usize,
) -> Vec<&'a str> {
    let lw = word.to_ascii_lowercase();
    let limit = (word.len() / 3).max(2);
    let mut scored: Vec<(usize, &'a str)> = candidates
        .into_iter()
        .filter_map(|c| {
            let d = distance(word, c);
            let lc = c.to_ascii_lowercase();
            let contains = lw.len() >= 3 && lc.len() >= 3 && (lc.contains(&lw) || lw.contains(&lc));
            (d <= limit || contains).then_some((if contains { d.min(limit) } else { d }, c))
        })
        .collect();
    scored.sort();
    scored.dedup_by(|a, b| a.1 == b.1);
    // A name that matches but for case is the answer.
    if scored.iter().any(|(_, c)| c.eq_ignore_ascii_case(word)) {
        scored.retain(|(_, c)| c.eq_ignore_ascii_case(word));
    }
    scored.into_iter().take(n).map(|(_, c)| c).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn distances() {
        assert_eq!(distance("name", "nmae"), 1);
        assert_eq!(distance("MOT_MOVE_HOME", "mot_move_home"), 0);
        assert_eq!(distance("abc", ""), 3);
    }

    #[test]
    fn nearest_names_first() {
        let c = [
            "MOT_MOVE_HOME",
            "MOT_MOVE_HOMED",
            "HW_REQ_INFO",
            "MOT_MOVE_STOP",
        ];
        assert_eq!(
            nearest("MOT_MOVE_HOM", c, 2),
            ["MOT_MOVE_HOME", "MOT_MOVE_HOMED"]
        );
        assert_eq!(nearest("HW_REQ_INOF", c, 3), ["HW_REQ_INFO"]);
        assert!(nearest("XYZZY", c, 3).is_empty());
    }
}
