"""The benchmarks and the named default's choice: ``bench``, ``bench-scale``, ``bench-stream``,
``default-choice`` (``make bench``, ``make bench-scale``, ``make bench-stream``, ``make default-choice``).
Argument parsing and printing only."""
from __future__ import annotations

from greenloop.experiments import default_choice
from greenloop.speed import bench, long_stream, scale


def _bench(sub) -> None:
    s = sub.add_parser("bench", help="the paper's pipeline as written vs the stream, and training, timed (bench.md)")
    s.add_argument("--out", default="results/bench", help="output folder (default results/bench)")
    s.add_argument("--dataset", default="data/synthetic-greenhouse",
                   help="sequence folder (default data/synthetic-greenhouse; random frames if missing)")
    s.add_argument("--quick", action="store_true", help="fewer repetitions, 1 seed, 2 epochs (< 1 min)")
    s.add_argument("--accuracy-seeds", type=int, default=10,
                   help="seeds of the 200-epoch accuracy comparison, plain vs fast (default 10: the notebooks' 0-4 and "
                        "five more, since one seed in ten can end several points below the rest; 0 skips it)")
    s.set_defaults(func=lambda a: print(bench.run(a.out, a.dataset, a.quick, a.accuracy_seeds)) or 0)


def _scale(sub) -> None:
    s = sub.add_parser("bench-scale", help="every retrieval index and the named default's decision at 10^4..10^6 frames")
    s.add_argument("--src", default="../shared/real/nordland", help="Nordland source (summer/, winter/)")
    s.add_argument("--out", default="results/bench", help="output folder")
    s.add_argument("--sizes", type=int, nargs="+", default=list(scale.SIZES))
    s.add_argument("--queries", type=int, nargs="+", default=[2000, 1000, 300], help="queries per size (same order as --sizes)")
    s.add_argument("--dim", type=int, default=64)
    s.add_argument("--decision-queries", type=int, default=2000, help="frames streamed through the whole decision at each size")
    s.add_argument("--decision-sizes", type=int, nargs="+", default=None, help="stored counts of the whole decision (default: --sizes)")
    s.add_argument("--note", default="", help="a sentence for the header (e.g. what shared the cores)")

    def run(a) -> int:
        if len(a.queries) != len(a.sizes):
            s.error("--queries needs one count per --sizes entry")
        scale.run(a.src, a.out, a.sizes, a.dim, a.queries, note=a.note, decision_queries=a.decision_queries,
                  decision_sizes=a.decision_sizes)
        return 0
    s.set_defaults(func=run)


def _stream(sub) -> None:
    s = sub.add_parser("bench-stream", help="a long augmented recording streamed through `detect --index hnsw`")
    s.add_argument("--src", default="../shared/real/nordland", help="Nordland source (summer/, winter/)")
    s.add_argument("--out", default="results/bench", help="output folder (stream100k.json, scale.md's section)")
    s.add_argument("--frames", type=int, default=100_000)
    s.add_argument("--work", default="/tmp/greenloop-stream",
                   help="folder for the recording's PNGs (about 6 kB a frame) and the state files")
    s.add_argument("--save-every", type=int, default=25_000, help="detect --save-every")
    s.add_argument("--note", default="", help="a sentence for the section (e.g. what shared the cores)")

    def run(a) -> int:
        r = long_stream.run(a.src, a.out, a.frames, a.work, save_every=a.save_every, note=a.note)
        print("\n".join(long_stream.section(r)))
        return 0
    s.set_defaults(func=run)


def _default_choice(sub) -> None:
    s = sub.add_parser("default-choice", help="the named default's windows, shift and thresholds, on tuning queries")
    s.add_argument("--nordland", default="data/nordland")
    s.add_argument("--gardenspoint", default="data/gardenspoint")
    s.add_argument("--synthetic", default="data/synthetic-greenhouse")
    s.add_argument("--out", default="results/default_choice")
    s.set_defaults(func=lambda a: print("\n".join(default_choice.run(a.nordland, a.gardenspoint, a.synthetic, a.out))) or 0)


def add_parser(sub) -> None:
    """The benchmark commands' arguments."""
    _bench(sub)
    _scale(sub)
    _stream(sub)
    _default_choice(sub)
