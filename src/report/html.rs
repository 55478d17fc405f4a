//! HTML building blocks of the report: escaping, the page shell (inline CSS and
//! JS, so a page needs no network and no server), and small helpers that every
//! page uses. Every string that can come from a scene file, a renderer or a
//! command line goes through [`escape`] before it reaches markup; the inline
//! script reads its data from (escaped) DOM attributes, never from interpolated
//! strings, so no name can reach a script context.

use std::fmt::Write;

/// Escapes text for HTML element content *and* quoted attribute values, so one
/// function is enough everywhere (no context where a lesser escape could slip).
pub fn escape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        if let Some(entity) = markup_entity(c) {
            out.push_str(entity);
            continue;
        }
        match c {
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            // Control characters are invisible and can confuse viewers; show them.
            c if c.is_control() && c != '\n' && c != '\t' => {
                let _ = write!(out, "&#x{:x};", u32::from(c));
            }
            c => out.push(c),
        }
    }
    out
}

/// The entity for a character that opens markup or an entity in HTML text
/// (`&`, `<`, `>`): the list [`escape`] and the gate's markdown escape (markdown
/// renders inline HTML) share.
pub fn markup_entity(c: char) -> Option<&'static str> {
    match c {
        '&' => Some("&amp;"),
        '<' => Some("&lt;"),
        '>' => Some("&gt;"),
        _ => None,
    }
}

/// Percent-encodes a relative URL path (our own file names are already safe;
/// this keeps a link valid even if one is not), leaving `/`, `#` and `.` alone.
pub fn url(path: &str) -> String {
    let mut out = String::with_capacity(path.len());
    for b in path.bytes() {
        if b.is_ascii_alphanumeric() || b"-_./#".contains(&b) {
            out.push(char::from(b));
        } else {
            let _ = write!(out, "%{b:02X}");
        }
    }
    out
}

/// A status word as a colored badge; the class carries the color, the title the reason.
pub fn badge(status: &str, title: &str) -> String {
    format!(
        "<span class=\"badge s-{cls}\" title=\"{t}\">{s}</span>",
        cls = status_class(status),
        t = escape(title),
        s = escape(status)
    )
}

/// CSS class suffix of a status; unknown statuses get a neutral look instead of
/// being trusted into a class name.
pub fn status_class(status: &str) -> &'static str {
    use crate::vocab::{RenderStatus, Status};
    match (Status::parse(status), RenderStatus::parse(status)) {
        (Some(Status::Pass), _) | (_, Some(RenderStatus::Ok)) => "pass",
        (Some(Status::Fail), _) => "fail",
        (Some(Status::Error), _) => "error",
        (Some(Status::Skipped), _) => "skipped",
        (Some(Status::ExpectedFail), _) => "xfail",
        (Some(Status::UnexpectedPass), _) => "xpass",
        _ => "other",
    }
}

/// A command in a copyable code block.
pub fn command_block(cmd: &str) -> String {
    format!("<pre class=\"cmd\"><code>{}</code></pre>", escape(cmd))
}

/// A complete page: `title` is plain text (escaped here), `body` is markup built
/// by the caller from escaped pieces.
pub fn page(title: &str, body: &str) -> String {
    let body = format!("{body}\n<script>{JS}</script>");
    shell(title, &body)
}

/// A page like [`page`] without the report's script (it serves images and
/// flip views, which such pages do not have): the benchmarks' pages.
pub fn page_without_script(title: &str, body: &str) -> String {
    shell(title, body)
}

/// The document around `body`: the head on one line with [`CSS`] inlined
/// (a page needs no file beside it, and pages written together into
/// several folders share no copied sheet), the body on lines of its own.
fn shell(title: &str, body: &str) -> String {
    let css: String = CSS.lines().map(str::trim).collect();
    format!(
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\
         <meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\
         <title>{}</title><style>{css}</style></head>\n<body>\n{body}\n</body></html>\n",
        escape(title)
    )
}

/// Styles: one small sheet, inlined in every page (no external files to
/// lose), one line there; written here a rule or two a line to be read.
pub const CSS: &str = r#"
body{font:14px/1.4 system-ui,-apple-system,"Segoe UI",sans-serif;margin:16px 24px;color:#1b1b1b;background:#fafafa}
h1{font-size:22px;margin:4px 0 8px}h2{font-size:18px;margin:22px 0 8px;border-bottom:1px solid #ddd}
h3{font-size:15px;margin:14px 0 6px}
a{color:#0b57d0}
table{border-collapse:collapse;margin:6px 0;background:#fff}
th,td{border:1px solid #d6d6d6;padding:3px 6px;text-align:left;vertical-align:top}
th{background:#f0f0f0}
td.num{text-align:right;font-variant-numeric:tabular-nums}
.badge{display:inline-block;padding:0 6px;border-radius:3px;font-size:12px;font-weight:600;white-space:nowrap}
.s-pass{background:#d8f0d8;color:#14532d}.s-fail{background:#f8c9c9;color:#7f1d1d}
.s-error{background:#f3c3f3;color:#701a75}.s-skipped{background:#e6e6e6;color:#404040}
.s-xfail{background:#fde9b8;color:#713f12}.s-xpass{background:#c8dcf8;color:#1e3a8a}
.s-other{background:#eee;color:#000}
.scroll{max-width:100%;overflow-x:auto}
.matrix td{text-align:center;white-space:nowrap}
tr.cause td{font-weight:600}tr.cause td.reason{font-weight:400}tr.members>td{border-top:none;padding-left:24px}.matrix td.scene{text-align:left}
.reason{font-size:12px;color:#444;max-width:60em;word-break:break-word}
pre.cmd{background:#f2f2f2;border:1px solid #ddd;padding:4px 6px;margin:2px 0;white-space:pre-wrap;word-break:break-all;font-size:12px}
.grid{display:grid;grid-template-columns:repeat(auto-fill,minmax(170px,1fr));gap:10px}
figure{margin:0;background:#fff;border:1px solid #ddd;padding:6px}
figure img,.flip-view{image-rendering:pixelated;width:100%;height:auto;display:block;background:#000}
figcaption{font-size:12px;margin-top:4px}
figcaption button{font-size:11px;padding:0 5px;margin-left:4px}
.flip{display:flex;gap:16px;align-items:flex-start;flex-wrap:wrap;background:#fff;border:1px solid #ddd;padding:8px}
.flip-stage{width:512px;max-width:100%;cursor:crosshair}
.flip-controls label{display:block;margin:4px 0}
.legend span.sw{display:inline-block;width:12px;height:12px;border:1px solid #888;vertical-align:middle;margin:0 3px 0 8px}
.note{background:#fff7d6;border:1px solid #e8d48a;padding:6px 8px;margin:8px 0}
.muted{color:#666}
.counts{font-size:11px;color:#555;font-variant-numeric:tabular-nums}
.cls{display:inline-block;padding:0 5px;border-radius:3px;font-size:12px;font-weight:600}
.c-edge{background:#ffe9a8}.c-tie{background:#d7e8ff}.c-crack{background:#ffd1b3}.c-interior{background:#f8c9c9}.c-other{background:#eee}
details{margin:4px 0}
svg{background:#fff;border:1px solid #ddd}
"#;

/// The only script: marks every image as loaded or failed and records where
/// the matrix's box ends against the page's width (so a headless browser
/// test can read both from the DOM), and drives the flip viewers.
/// It reads everything from the DOM; nothing is interpolated into it.
const JS: &str = r#"
(function(){
  function tally(){
    var ok=0,bad=0,pending=0;
    document.querySelectorAll('img').forEach(function(i){
      if(i.dataset.loaded==='1')ok++;else if(i.dataset.loaded==='0')bad++;else pending++;
    });
    document.body.dataset.imagesLoaded=ok;document.body.dataset.imagesFailed=bad;document.body.dataset.imagesPending=pending;
  }
  function mark(i){
    if(!i.complete)return;
    i.dataset.loaded=(i.naturalWidth>0)?'1':'0';
  }
  document.querySelectorAll('img').forEach(function(i){
    i.addEventListener('load',function(){i.dataset.loaded=(i.naturalWidth>0)?'1':'0';tally();});
    i.addEventListener('error',function(){i.dataset.loaded='0';tally();});
    mark(i);
  });
  tally();
  function measure(){
    var m=document.getElementById('matrix-box');if(!m)return;
    var r=m.getBoundingClientRect(),d=document.body.dataset;
    d.matrixRight=Math.ceil(r.right);d.viewportWidth=document.documentElement.clientWidth;
    d.matrixScrolls=(m.scrollWidth>m.clientWidth)?'1':'0';
  }
  measure();window.addEventListener('load',measure);window.addEventListener('resize',measure);
  document.querySelectorAll('.flip').forEach(function(f){
    var view=f.querySelector('.flip-view'),a=f.querySelector('.flip-a'),b=f.querySelector('.flip-b');
    var label=f.querySelector('.flip-label'),pos=f.querySelector('.flip-pos'),hover=f.querySelector('.flip-hover');
    var shown='a';
    function sel(w){return w==='a'?a:b;}
    function show(w){
      shown=w;var s=sel(w);view.src=s.value;
      label.textContent=(w==='a'?'A: ':'B: ')+s.options[s.selectedIndex].text;
    }
    a.addEventListener('change',function(){show('a');});
    b.addEventListener('change',function(){show('b');});
    view.addEventListener('mouseenter',function(){if(hover.checked)show('b');});
    view.addEventListener('mouseleave',function(){if(hover.checked)show('a');pos.textContent='';});
    view.addEventListener('click',function(){show(shown==='a'?'b':'a');});
    view.addEventListener('mousemove',function(e){
      if(!view.naturalWidth)return;
      var r=view.getBoundingClientRect();
      var x=Math.floor((e.clientX-r.left)/r.width*view.naturalWidth),y=Math.floor((e.clientY-r.top)/r.height*view.naturalHeight);
      pos.textContent='pixel ('+x+', '+y+')';
    });
    f.parentNode.querySelectorAll('button[data-flip]').forEach(function(btn){
      btn.addEventListener('click',function(){
        var t=sel(btn.dataset.flip);t.value=btn.dataset.src;
        show(btn.dataset.flip);
        f.scrollIntoView({behavior:'smooth',block:'nearest'});
      });
    });
    show('a');
  });
})();
"#;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_status_word_has_its_own_class_and_nothing_else_does() {
        use crate::vocab::{RenderStatus, Status};
        for s in Status::ALL {
            assert_ne!(status_class(s.as_str()), "other", "{s}");
        }
        for s in RenderStatus::ALL {
            assert_ne!(status_class(s.as_str()), "other", "{s}");
        }
        let classes: std::collections::BTreeSet<_> = Status::ALL
            .iter()
            .map(|s| status_class(s.as_str()))
            .collect();
        assert_eq!(
            classes.len(),
            Status::ALL.len(),
            "two statuses share a look"
        );
        for unknown in ["", "PASS", "fail ", "\"><script>"] {
            assert_eq!(status_class(unknown), "other");
        }
    }

    #[test]
    fn escapes_everything_that_can_open_markup() {
        assert_eq!(
            escape("<script>alert('x')</script> & \"q\""),
            "&lt;script&gt;alert(&#39;x&#39;)&lt;/script&gt; &amp; &quot;q&quot;"
        );
        assert_eq!(escape("a\u{1}b"), "a&#x1;b");
    }

    #[test]
    fn urls_keep_safe_paths_and_encode_the_rest() {
        assert_eq!(url("img/a-b/c.png#x"), "img/a-b/c.png#x");
        assert_eq!(url("a b\"<"), "a%20b%22%3C");
    }

    #[test]
    fn unknown_statuses_get_a_neutral_class() {
        assert!(badge("\" onmouseover=\"x", "").contains("s-other"));
        assert!(!badge("\" onmouseover=\"x", "").contains("\" onmouseover"));
    }
}
