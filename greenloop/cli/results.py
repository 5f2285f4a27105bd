"""The commands that read results folders and write the study's pages: ``tables``, ``verdict``,
``summary``, ``provenance``, ``verify``, ``book`` (``make readme``, ``make book``, ``make verify``
call them). Argument parsing and printing only; the work is in ``greenloop.study``."""
from __future__ import annotations

from pathlib import Path

from greenloop.study import book, provenance, report, summary, verdict, verify


def _folders(ap, folders) -> None:
    """Refuse a results folder that does not exist (exit status 2, one line)."""
    missing = [d for d in folders if not Path(d).is_dir()]
    if missing:
        ap.error(f"no such results folder: {', '.join(missing)} (run `make all` first, or name another)")


def _tables(sub) -> None:
    s = sub.add_parser("tables", help="assemble a results folder's tables.md, or one table across folders",
                       description="Assemble the notebooks' tables from a results folder (tables.md), or with "
                                   "--datasets / --coverage write one table across results folders.")
    s.add_argument("results", nargs="*", default=["results"], help="results folder(s) (default results)")
    group = s.add_mutually_exclusive_group()
    group.add_argument("--datasets", metavar="OUT", help="write one table across the results folders (.md, .csv)")
    group.add_argument("--coverage", metavar="OUT", help="write the papers' coverage read from the results folders")

    def run(args) -> int:
        _folders(s, args.results)
        if args.datasets:
            print(report.write_cross_dataset(args.results, args.datasets))
        elif args.coverage:
            print(report.write_coverage(args.results, args.coverage))
        elif len(args.results) != 1:
            s.error("give one results folder (or --datasets / --coverage for several)")
        else:
            print(report.assemble_tables(args.results[0]))
        return 0
    s.set_defaults(func=run)


def _written(ap, folders, write) -> int:
    """Check the results folders, run ``write()`` and print the file it wrote."""
    _folders(ap, folders)
    print(write())
    return 0


def _pages(sub) -> None:
    v = sub.add_parser("verdict", help="does each paper's claim hold? results/verdict.md and the README's block")
    v.add_argument("results", nargs="+", help="results folders, e.g. results results/nordland results/gardenspoint")
    v.add_argument("--out", default="results/verdict.md", help="the markdown page (a .csv beside it)")
    v.add_argument("--readme", help="a Markdown file whose <!-- verdict:start --> block to refill")
    v.set_defaults(func=lambda a: _written(v, a.results, lambda: verdict.write(a.results, a.out, a.readme)))
    m = sub.add_parser("summary", help="every leaderboard row, the main paper's detector, the targets (summary.md)")
    m.add_argument("results", nargs="+", help="results folders (results results/nordland ...)")
    m.add_argument("--out", default=None, help="file to write (default: summary.md in the first folder)")
    m.add_argument("--bench", default=None, help="benchmark folder (default: bench in the first folder)")
    m.add_argument("--readme", help="a Markdown file whose <!-- standing:start --> block to refill")
    m.set_defaults(func=lambda a: _written(m, a.results, lambda: summary.write_summary(
        a.results, a.out or Path(a.results[0]) / "summary.md", a.bench, a.readme)))
    p = sub.add_parser("provenance", help="each notebook's commit, environment, CPU, date and duration (PROVENANCE.md)")
    p.add_argument("results", nargs="+", help="results folders (results results/nordland ...)")
    p.add_argument("--out", default=None, help="file to write (default: PROVENANCE.md in the first folder)")
    p.set_defaults(func=lambda a: _written(p, a.results, lambda: provenance.write_provenance(
        a.results, a.out or Path(a.results[0]) / "PROVENANCE.md")))
    b = sub.add_parser("book", help="the rendered book of every executed notebook (build/book)")
    b.add_argument("results", nargs="+", help="results folders, the top one first: results results/nordland ...")
    b.add_argument("--out", default="build/book", help="the site's folder (replaced)")
    b.set_defaults(func=lambda a: _written(b, a.results, lambda: book.build(a.results, a.out)))


def _verify(sub) -> None:
    s = sub.add_parser("verify", help="did a rerun reproduce the committed tables, outside timing?",
                       description="Compare RERUN's tables with REFERENCE's cell by cell, timing columns skipped; "
                                   "exit 0 (all reproduced), 1 (not), 2 (usage).")
    s.add_argument("reference", help="committed results folder (results, or results/<dataset>)")
    s.add_argument("rerun", help="the rerun's results folder (make all RESULTS=...)")
    s.add_argument("--rtol", type=float, default=verify.RTOL, help=f"relative tolerance for non-integer numbers ({verify.RTOL:g})")

    def run(args) -> int:
        _folders(s, [args.reference, args.rerun])
        lines, ok = verify.check(args.reference, args.rerun, args.rtol)
        print("\n".join(lines))
        return 0 if ok else 1
    s.set_defaults(func=run)


def add_parser(sub) -> None:
    """The results commands' arguments."""
    _tables(sub)
    _pages(sub)
    _verify(sub)
