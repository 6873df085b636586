//! File-name patterns with `{camera}`, `{period}`, `{set}`, `{shift}` and
//! `{index}` placeholders, compiled once and matched by backtracking.

use super::*;

#[derive(Clone, Debug, PartialEq)]
pub(super) enum Token {
    Literal(String),
    Camera,
    Period,
    Set(Option<usize>),
    Shift(Option<usize>),
    Index(Option<usize>),
}

/// A compiled file-name pattern.
#[derive(Clone, Debug, PartialEq)]
pub struct Pattern {
    text: String,
    tokens: Vec<Token>,
}

/// What a pattern read from one file name.
#[derive(Clone, Debug, Default, PartialEq)]
pub(super) struct Captures {
    pub(super) camera: Option<String>,
    pub(super) period: Option<String>,
    pub(super) set: Option<u64>,
    pub(super) shift: Option<u64>,
    pub(super) index: Option<u64>,
}

impl Pattern {
    pub fn parse(text: &str) -> Result<Pattern, ImportFault> {
        let bad = |problem: String| ImportFault::BadPattern { pattern: text.to_string(), problem };
        let mut tokens = Vec::new();
        let mut literal = String::new();
        let mut rest = text;
        while let Some(open) = rest.find('{') {
            literal.push_str(&rest[..open]);
            let close = rest[open..].find('}').ok_or_else(|| bad("a '{' is not closed".into()))? + open;
            let inner = &rest[open + 1..close];
            let (name, width) = match inner.split_once(':') {
                Some((n, w)) => {
                    let width: usize = w
                        .trim_start_matches('0')
                        .parse()
                        .ok()
                        .filter(|&w| w > 0 && w < 20)
                        .ok_or_else(|| bad(format!("{{{inner}}}: the width must be a number such as 02")))?;
                    (n, Some(width))
                }
                None => (inner, None),
            };
            if !literal.is_empty() {
                tokens.push(Token::Literal(std::mem::take(&mut literal)));
            }
            let token = match (name, width) {
                ("camera", None) => Token::Camera,
                ("period", None) => Token::Period,
                ("set", w) => Token::Set(w),
                ("shift", w) => Token::Shift(w),
                ("index", w) => Token::Index(w),
                ("camera" | "period", Some(_)) => return Err(bad(format!("{{{name}}} takes no width"))),
                _ => {
                    return Err(bad(format!(
                        "unknown placeholder {{{inner}}}; use {{camera}}, {{period}}, {{set}}, {{shift}} or {{index}}"
                    )));
                }
            };
            if tokens.iter().any(|t| std::mem::discriminant(t) == std::mem::discriminant(&token)) {
                return Err(bad(format!("{{{name}}} appears twice")));
            }
            tokens.push(token);
            rest = &rest[close + 1..];
        }
        literal.push_str(rest);
        if literal.contains('}') {
            return Err(bad("a '}' has no '{'".into()));
        }
        if !literal.is_empty() {
            tokens.push(Token::Literal(literal));
        }
        let has = |f: fn(&Token) -> bool| tokens.iter().any(f);
        let index = has(|t| matches!(t, Token::Index(_)));
        let shift = has(|t| matches!(t, Token::Shift(_)));
        let set = has(|t| matches!(t, Token::Period | Token::Set(_)));
        if index && (shift || set) {
            return Err(bad(
                "number the images either with {index} (through all sets) or with {period} (or {set}) and {shift}, \
                 not both"
                    .into(),
            ));
        }
        if !(index || (shift && set)) {
            return Err(bad(
                "needs {index}, or {shift} together with {period} or {set}, to tell the images apart".into()
            ));
        }
        if has(|t| matches!(t, Token::Period)) && has(|t| matches!(t, Token::Set(_))) {
            return Err(bad("use {period} or {set}, not both".into()));
        }
        for pair in tokens.windows(2) {
            if !matches!(pair[0], Token::Literal(_)) && !matches!(pair[1], Token::Literal(_)) {
                let unsized_number =
                    |t: &Token| matches!(t, Token::Set(None) | Token::Shift(None) | Token::Index(None));
                if matches!(pair[0], Token::Camera) || unsized_number(&pair[0]) || matches!(pair[0], Token::Period) {
                    return Err(bad(
                        "two placeholders touch; put text between them or give the first a width, e.g. {shift:02}"
                            .into(),
                    ));
                }
            }
        }
        Ok(Pattern { text: text.to_string(), tokens })
    }

    pub fn text(&self) -> &str {
        &self.text
    }

    pub(super) fn has_camera(&self) -> bool {
        self.tokens.contains(&Token::Camera)
    }

    pub(super) fn uses_index(&self) -> bool {
        self.tokens.iter().any(|t| matches!(t, Token::Index(_)))
    }

    pub(super) fn uses_period(&self) -> bool {
        self.tokens.contains(&Token::Period)
    }

    pub(super) fn captures(&self, text: &str) -> Option<Captures> {
        let mut caps = Captures::default();
        match_from(&self.tokens, text, &mut caps).then_some(caps)
    }
}

/// Backtracking match of `tokens` against all of `text`.
pub(super) fn match_from(tokens: &[Token], text: &str, caps: &mut Captures) -> bool {
    let Some((first, rest)) = tokens.split_first() else {
        return text.is_empty();
    };
    match first {
        Token::Literal(l) => text.strip_prefix(l.as_str()).is_some_and(|t| match_from(rest, t, caps)),
        Token::Camera => {
            // Shortest first: `cam{camera}_{index}` reads `camL_3` as L.
            for (end, c) in text.char_indices().map(|(i, c)| (i + c.len_utf8(), c)) {
                if c == '/' {
                    break;
                }
                if match_from(rest, &text[end..], caps) {
                    caps.camera = Some(text[..end].to_string());
                    return true;
                }
            }
            false
        }
        Token::Period => {
            let run = text.bytes().take_while(|b| b.is_ascii_digit() || *b == b'.').count();
            for end in (1..=run).rev() {
                let s = &text[..end];
                if s.starts_with('.') || s.ends_with('.') || s.matches('.').count() > 1 {
                    continue;
                }
                if match_from(rest, &text[end..], caps) {
                    caps.period = Some(s.to_string());
                    return true;
                }
            }
            false
        }
        Token::Set(width) | Token::Shift(width) | Token::Index(width) => {
            let run = text.bytes().take_while(u8::is_ascii_digit).count();
            let ends: Vec<usize> = match width {
                Some(w) if *w <= run => vec![*w],
                Some(_) => Vec::new(),
                None => (1..=run.min(18)).rev().collect(),
            };
            for end in ends {
                let Ok(n) = text[..end].parse::<u64>() else { continue };
                if match_from(rest, &text[end..], caps) {
                    match first {
                        Token::Set(_) => caps.set = Some(n),
                        Token::Shift(_) => caps.shift = Some(n),
                        _ => caps.index = Some(n),
                    }
                    return true;
                }
            }
            false
        }
    }
}
