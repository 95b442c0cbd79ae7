#!/usr/bin/env python3
"""Checks the relative links of README.md and of every page of the book in docs/ (CI runs it from
.ci/run, after `mdbook build docs`), and of the other READMEs that link into the book (the starter
kit's, the Python packages', deploy/README.md, which the book includes). Standard library only.

A link is checked when its target has no scheme (http:, mailto:, ...): the path, taken relative to
the page that holds the link, must name a file or folder that exists in the repository, and an
`#anchor` must name a heading of the target page (or of the page itself for `#anchor` alone) under
mdBook's rule for heading ids: the heading's text without its markup, lowercased, whitespace to
'-', every character that is neither alphanumeric nor '-' or '_' dropped, a repeated id given
'-1', '-2', ... as mdBook does. Explicit ids (`{#id}` after a heading, `id="..."` in HTML) count
too. Links in fenced code blocks and code spans are not links and are skipped.

Also checked: every page of docs/ (outside the build output docs/book/) is listed in
docs/SUMMARY.md, so no chapter is left out of the book.

Usage: python3 scripts/check-book-links.py [EXTRA.md ...]   (extra Markdown files to check too)
Exit 0 when every link resolves; 1 with the list of broken links otherwise.
"""

import glob
import os
import re
import sys
from urllib.parse import unquote

ROOT = os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
BOOK = os.path.join(ROOT, "docs")
BUILD = os.path.join(BOOK, "book")

# READMEs outside docs/ that link into the book: a renamed page or heading breaks them too.
OTHER_READMES = [
    "starter-kit/README.md",
    "starter-kit/baselines/*/README.md",
    "python/README.md",
    "python/*/README.md",
    "deploy/README.md",
]

FENCE = re.compile(r"^\s{0,3}(`{3,}|~{3,})")
HEADING = re.compile(r"^\s{0,3}(#{1,6})\s+(.*?)\s*#*\s*$")
SETEXT = re.compile(r"^\s{0,3}(=+|-+)\s*$")
CODE_SPAN = re.compile(r"(`+)(.+?)\1")
# [text](target "title") and ![alt](target); the text may hold one level of brackets.
INLINE_LINK = re.compile(r"!?\[(?:[^\[\]]|\[[^\[\]]*\])*\]\(\s*<?([^)\s>]*)>?(?:\s+\"[^\"]*\")?\s*\)")
REF_DEF = re.compile(r"^\s{0,3}\[[^\]]+\]:\s*<?(\S+?)>?(?:\s+.*)?$")
HTML_ATTR = re.compile(r"<(?:a|img)\b[^>]*?\b(?:href|src)=\"([^\"]*)\"", re.I)
HTML_ID = re.compile(r"\bid=\"([^\"]+)\"")
EXPLICIT_ID = re.compile(r"\{#([^}\s]+)[^}]*\}\s*$")
SCHEME = re.compile(r"^[A-Za-z][A-Za-z0-9+.-]*:")


def strip_markup(text):
    """A heading's text as mdBook sees it: code spans keep their content, links their text,
    emphasis markers and HTML tags go."""
    out, last = [], 0
    for m in CODE_SPAN.finditer(text):
        out.append(strip_inline(text[last : m.start()]))
        out.append(m.group(2).strip())
        last = m.end()
    out.append(strip_inline(text[last:]))
    return "".join(out)


def strip_inline(text):
    text = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", text)
    text = re.sub(r"<[^>]+>", "", text)
    return re.sub(r"\*+", "", text)


def normalize_id(text):
    out = []
    for ch in text:
        if ch.isalnum() or ch in "_-":
            out.append(ch.lower() if ch.isascii() else ch)
        elif ch.isspace():
            out.append("-")
    return "".join(out)


def lines_outside_code(path):
    """(line number, text) of each line outside fenced code blocks."""
    with open(path, encoding="utf-8") as f:
        lines = f.read().split("\n")
    fence = None
    for no, line in enumerate(lines, 1):
        m = FENCE.match(line)
        if fence is None and m:
            fence = m.group(1)[0] * len(m.group(1))
            continue
        if fence is not None:
            if line.strip().startswith(fence):
                fence = None
            continue
        yield no, line


_anchor_cache: dict[object, set[str]] = {}


def anchors_of(path):
    if path in _anchor_cache:
        return _anchor_cache[path]
    anchors, seen = set(), {}
    prev = None
    for _, line in lines_outside_code(path):
        text = None
        m = HEADING.match(line)
        if m:
            text = m.group(2)
        elif prev is not None and prev.strip() and SETEXT.match(line) and not HEADING.match(prev):
            if not re.match(r"^\s*([-*|]|\d+\.)", prev):
                text = prev.strip()
        if text is not None:
            e = EXPLICIT_ID.search(text)
            if e:
                anchors.add(e.group(1))
            else:
                base = normalize_id(strip_markup(text))
                n = seen.get(base, 0)
                seen[base] = n + 1
                anchors.add(base if n == 0 else f"{base}-{n}")
        for hid in HTML_ID.findall(line):
            anchors.add(hid)
        prev = line
    _anchor_cache[path] = anchors
    return anchors


def links_of(path):
    for no, line in lines_outside_code(path):
        bare = CODE_SPAN.sub(lambda m: " " * len(m.group(0)), line)
        for m in INLINE_LINK.finditer(bare):
            yield no, m.group(1)
        m = REF_DEF.match(bare)
        if m:
            yield no, m.group(1)
        for m in HTML_ATTR.finditer(bare):
            yield no, m.group(1)


def check(path):
    broken = []
    for no, target in links_of(path):
        if not target or SCHEME.match(target) or target.startswith("//"):
            continue
        file_part, _, anchor = target.partition("#")
        file_part = unquote(file_part)
        if file_part:
            dest = os.path.normpath(os.path.join(os.path.dirname(path), file_part))
            if not os.path.exists(dest):
                broken.append((no, target, "no such file"))
                continue
            if not dest.startswith(ROOT + os.sep) and dest != ROOT:
                broken.append((no, target, "outside the repository"))
                continue
        else:
            dest = path
        if anchor and dest.endswith(".md") and os.path.isfile(dest):
            if unquote(anchor) not in anchors_of(dest):
                where = os.path.relpath(dest, ROOT)
                broken.append((no, target, f"no heading with id '{anchor}' in {where}"))
    return broken


def book_pages():
    pages = []
    for dirpath, dirnames, filenames in os.walk(BOOK):
        if os.path.abspath(dirpath) == BUILD or os.path.abspath(dirpath).startswith(BUILD + os.sep):
            dirnames[:] = []
            continue
        dirnames.sort()
        pages += [os.path.join(dirpath, f) for f in sorted(filenames) if f.endswith(".md")]
    return pages


def summary_targets():
    summary = os.path.join(BOOK, "SUMMARY.md")
    listed = set()
    for _, target in links_of(summary):
        if target and not SCHEME.match(target):
            listed.add(os.path.normpath(os.path.join(BOOK, unquote(target.partition("#")[0]))))
    return listed


def main(argv):
    files = [os.path.join(ROOT, "README.md")] + book_pages()
    for pattern in OTHER_READMES:
        files += sorted(glob.glob(os.path.join(ROOT, pattern)))
    files += [os.path.abspath(a) for a in argv]
    problems = []
    for path in files:
        for no, target, why in check(path):
            problems.append(f"{os.path.relpath(path, ROOT)}:{no}: ({target}): {why}")
    summary = os.path.join(BOOK, "SUMMARY.md")
    if os.path.exists(summary):
        listed = summary_targets()
        for page in book_pages():
            if page != summary and page not in listed:
                problems.append(f"{os.path.relpath(page, ROOT)}: not listed in docs/SUMMARY.md")
    else:
        problems.append("docs/SUMMARY.md: missing")
    if problems:
        print(f"check-book-links: {len(problems)} broken link(s) or unlisted page(s):")
        for p in problems:
            print("  " + p)
        return 1
    print(f"check-book-links: {len(files)} files, every relative link resolves")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
