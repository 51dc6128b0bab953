//! Seeded mutations of valid files for the fuzz-style property tests (parsers_fuzz,
//! hostile_inputs): truncations, bit flips, extreme words over binary fields, swapped fields,
//! extreme numbers in place of numbers.

pub struct Lcg(pub u64);
impl Lcg {
    pub fn next(&mut self) -> u64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        self.0 >> 17
    }
    pub fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

pub const EXTREMES: [&str; 14] = [
    "1e308",
    "-1e308",
    "nan",
    "inf",
    "-inf",
    "-0",
    "1e-320",
    "0",
    "99999",
    "-5",
    "90",
    "18446744073709551615",
    "4294967296",
    "1e39",
];

/// Binary values written over 1, 2, 4 or 8 bytes: sizes, offsets and floats at their extremes.
pub fn extreme_word(rng: &mut Lcg) -> Vec<u8> {
    let v: [Vec<u8>; 12] = [
        u64::MAX.to_le_bytes().to_vec(),
        (1u64 << 32).to_le_bytes().to_vec(),
        (1u64 << 62).to_le_bytes().to_vec(),
        0u64.to_le_bytes().to_vec(),
        1u64.to_le_bytes().to_vec(),
        u32::MAX.to_le_bytes().to_vec(),
        0x7fff_ffffu32.to_le_bytes().to_vec(),
        f32::NAN.to_le_bytes().to_vec(),
        f32::INFINITY.to_le_bytes().to_vec(),
        (-1.0f32).to_le_bytes().to_vec(),
        1e300f64.to_le_bytes().to_vec(),
        f64::NAN.to_le_bytes().to_vec(),
    ];
    v[rng.below(v.len())].clone()
}

/// One random mutation of `bytes`; `header`: how many leading bytes hold the structure (binary
/// mutations hit there half of the time); `text`: whether text mutations apply.
pub fn mutate(bytes: &[u8], rng: &mut Lcg, header: usize, text: bool) -> Vec<u8> {
    let mut t = bytes.to_vec();
    let kinds = if text { 5 } else { 3 };
    let pos = |rng: &mut Lcg, len: usize| {
        if rng.below(2) == 0 {
            rng.below(header.min(len))
        } else {
            rng.below(len)
        }
    };
    match rng.below(kinds) {
        0 => t.truncate(pos(rng, t.len())),
        1 => {
            for _ in 0..1 + rng.below(4) {
                let i = pos(rng, t.len());
                if i < t.len() {
                    t[i] ^= 1 << rng.below(8);
                }
            }
        }
        2 => {
            let w = extreme_word(rng);
            let i = pos(rng, t.len());
            let n = [1, 2, 4, 8][rng.below(4)].min(w.len());
            for k in 0..n {
                if i + k < t.len() {
                    t[i + k] = w[k];
                }
            }
        }
        3 => {
            // swap two fields of one line, or two lines
            let s = String::from_utf8_lossy(&t).into_owned();
            let mut lines: Vec<String> = s.lines().map(str::to_owned).collect();
            if lines.len() > 2 {
                let k = rng.below(lines.len());
                let mut fields: Vec<String> =
                    lines[k].split([',', ' ']).map(str::to_owned).collect();
                if fields.len() > 1 {
                    let (a, b) = (rng.below(fields.len()), rng.below(fields.len()));
                    fields.swap(a, b);
                    lines[k] = fields.join(if lines[k].contains(',') { "," } else { " " });
                } else {
                    let j = rng.below(lines.len());
                    lines.swap(k, j);
                }
            }
            t = (lines.join("\n") + "\n").into_bytes();
        }
        _ => {
            // an extreme number in place of a number
            let s = String::from_utf8_lossy(&t).into_owned();
            let b = s.as_bytes();
            let mut spans = Vec::new();
            let mut i = 0;
            while i < b.len() {
                if b[i].is_ascii_digit() {
                    let j0 = i;
                    while i < b.len() && (b[i].is_ascii_digit() || b[i] == b'.') {
                        i += 1;
                    }
                    spans.push((j0, i));
                } else {
                    i += 1;
                }
            }
            if !spans.is_empty() {
                let (a, e) = spans[rng.below(spans.len())];
                let x = EXTREMES[rng.below(EXTREMES.len())];
                t = format!("{}{x}{}", &s[..a], &s[e..]).into_bytes();
            }
        }
    }
    t
}
