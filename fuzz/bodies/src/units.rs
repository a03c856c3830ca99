//! Physical units (`units`): stage, scale and controller options from any text, model strings
//! as HW_GET_INFO may carry them, conversions of any raw value under any counts per unit and
//! family, and the per-device `Tracker` fed HW_GET_INFO and motion frames built from the input.
//!
//! Input: `[flags, counts (8 bytes, an f64's bits), raw (8 bytes), texts...]`: the texts,
//! separated by NUL, are a stage, a scale, a controller and a model (`flags` says which options
//! are given). Checks: nothing panics on any text; what parses is consistent (`--scale`: a
//! positive finite count and a unit; options empty only when none was given); every conversion
//! has a positive finite factor or none, converts raw values as `raw / factor` and back within
//! rounding, names a unit; `round_sig` keeps 6 significant digits; the tracker's notices have
//! text and its scales keep the same rules; physical values of decoded fields follow them.

use aptscope_dissector::apt::{encode_named, phys, round_sig, AptFrame, Named};
use aptscope_dissector::table::{Maximum, Quantity};
use aptscope_dissector::units::{
    model, nearest_stage_names, parse_scale, parse_stage, resolve, stage_rows, Family, Resolution,
    Scale, StageChoice, Tracker, UnitsOpts,
};
use aptscope_dissector::Table;

/// The rules every conversion keeps.
fn check_scale(s: &Scale, raw: f64) {
    let _ = s.describe();
    for q in Quantity::ALL {
        let f = s.factor(q);
        if let Some(f) = f {
            assert!(f.is_finite() && f > 0.0, "{q:?}: factor {f}");
        }
        match (s.convert(q, raw), f) {
            (None, None) => {}
            (Some((x, u)), Some(f)) => {
                assert_eq!(u, s.unit_of(q));
                assert!(
                    x == raw / f || (x.is_nan() && raw.is_nan()),
                    "{q:?}: {raw}/{f} = {x}"
                );
                // Back within rounding, unless the quotient under- or overflowed.
                if x.is_normal() && raw.is_normal() && (x * f).is_finite() {
                    let back = x * f;
                    assert!(
                        (back - raw).abs() <= 1e-9 * raw.abs(),
                        "{q:?}: {raw} → {x} → {back}"
                    );
                }
            }
            (c, f) => panic!("{q:?}: convert {c:?} with factor {f:?}"),
        }
    }
    if s.counts_per_unit.is_finite() && s.counts_per_unit > 0.0 {
        assert_eq!(s.factor(Quantity::Pos), Some(s.counts_per_unit));
    }
}

fn check_resolution(r: &Resolution, raw: f64) {
    match r {
        Resolution::Scale(s) => check_scale(s, raw),
        Resolution::Raw(why) => assert!(!why.is_empty()),
        Resolution::None => {}
    }
}

/// The body of the target: panics when a check fails.
pub fn fuzz(data: &[u8]) {
    let flags = data.first().copied().unwrap_or(0);
    let word = |at: usize| {
        let mut b = [0u8; 8];
        for (i, x) in data.iter().skip(at).take(8).enumerate() {
            b[i] = *x;
        }
        f64::from_bits(u64::from_le_bytes(b))
    };
    let (counts, raw) = (word(1), word(9));
    let text = String::from_utf8_lossy(data.get(17..).unwrap_or(&[])).into_owned();
    // Each text cut at 200 characters: names are short, and the nearest-name search of an
    // unknown stage is quadratic in the length (the CLI's arguments are the user's own).
    let mut parts = text
        .split('\0')
        .map(|p| p.chars().take(200).collect::<String>());
    let mut next = || parts.next().unwrap_or_default();
    let (stage, scale, controller, model_name) = (next(), next(), next(), next());
    let (stage, scale, controller, model_name) = (&*stage, &*scale, &*controller, &*model_name);

    for s in [stage, scale, controller, model_name] {
        let _ = model(s);
        let _ = stage_rows(s);
        let _ = Family::parse(s);
        if let Ok(name) = parse_stage(s) {
            assert!(
                !stage_rows(name).is_empty(),
                "{s:?} parses as {name}, unknown"
            );
        }
        match parse_scale(s) {
            Ok(StageChoice::Custom {
                counts_per_unit,
                unit,
            }) => assert!(counts_per_unit.is_finite() && counts_per_unit > 0.0 && !unit.is_empty()),
            Ok(other) => panic!("--scale gave {other:?}"),
            Err(e) => assert!(!e.is_empty()),
        }
    }
    if flags & 0x40 != 0 {
        assert!(!nearest_stage_names(stage).is_empty());
    }
    let pick = |bit: u8, s| (flags & bit != 0).then_some(s);
    let (st, sc, co) = (pick(1, stage), pick(2, scale), pick(4, controller));
    match UnitsOpts::from_args(st, sc, co) {
        Ok(opts) => {
            assert_eq!(
                opts.is_empty(),
                st.is_none() && sc.is_none() && co.is_none()
            );
            check_resolution(&resolve(&opts, Some(model_name)), raw);
            check_resolution(&resolve(&opts, None), raw);
            tracker(opts, model_name, raw);
        }
        Err(e) => assert!(!e.is_empty()),
    }
    // Any counts per unit (negative, zero, NaN, infinite) under any family.
    let family = Family::ALL.get(usize::from(flags >> 4) % 5).copied();
    let mut s = Scale::new("fuzz", family, counts, scale);
    check_scale(&s, raw);
    s.set_maximum(Maximum::Volts, counts);
    if let Some((v, _)) = s.of_maximum(Maximum::Volts, raw) {
        assert!(v == raw / 100.0 * counts || v.is_nan());
    }
    check_scale(&s, raw);
    // Display rounding: 6 significant digits.
    let r = round_sig(raw);
    if raw.is_finite() {
        // Beneath 1e-290 the rounding (to 10^-300 at most) may give 0.
        let tolerance = (1e-5 * raw.abs()).max(1e-290);
        assert!((r - raw).abs() <= tolerance, "round_sig({raw}) = {r}");
    } else {
        assert!(
            r == raw || (r.is_nan() && raw.is_nan()),
            "round_sig({raw}) = {r}"
        );
    }
}

/// HW_GET_INFO naming `model_name`, then motion frames with the raw value, through a tracker.
fn tracker(opts: UnitsOpts, model_name: &str, raw: f64) {
    let t = Table::global();
    let mut tr = Tracker::new(opts);
    let n = |name, values, dst, src| Named {
        name,
        sub: None,
        values,
        form: None,
        dst,
        src,
    };
    let r = (raw as i32).to_string();
    let frames = [
        encode_named(
            t,
            &n("HW_GET_INFO", &[("model_number", model_name)], 0x01, 0x50),
        ),
        encode_named(
            t,
            &n(
                "MOT_MOVE_ABSOLUTE",
                &[("chan_ident", "1"), ("absolute_position", &r)],
                0x50,
                0x01,
            ),
        ),
        encode_named(
            t,
            &n(
                "MOT_GET_VELPARAMS",
                &[("chan_ident", "1"), ("max_vel", &r), ("acceleration", &r)],
                0x01,
                0x50,
            ),
        ),
        encode_named(
            t,
            &n(
                "PZ_GET_OUTPUTMAXVOLTS",
                &[("chan_ident", "1"), ("voltage", &r)],
                0x01,
                0x50,
            ),
        ),
    ];
    for b in frames.iter().flatten() {
        let f = AptFrame::decode(t, 0, b, false).expect("a frame");
        let (scale, notice) = tr.observe(0, &f);
        if let Some(nt) = notice {
            assert!(!nt.text().is_empty());
            check_resolution(&nt.resolution, raw);
        }
        if let Some(s) = scale {
            check_scale(s, raw);
        }
        for (fd, v) in f.fields() {
            let pct = fd.pct_of.is_some();
            if let (Some((x, _)), Some(q), Some(s), false) = (phys(fd, &v, scale), fd.q, scale, pct)
            {
                let f = s.factor(q).expect("converted, so a factor");
                assert_eq!(x, v.as_f64().unwrap_or(f64::NAN) / f);
            }
        }
    }
}
