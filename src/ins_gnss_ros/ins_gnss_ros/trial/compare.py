"""``trial compare``: are two replays' output bags the same, message by message?

Messages are compared decoded (field by field, NaN equal to NaN), topic by topic in log-time
order; ``/diagnostics`` is left out by default (its counters name code paths, not navigation).
The answer names, per topic, the message counts and the first message that differs with the
first field that differs, so that a refactoring or a speed-up can show that it changed nothing.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from ins_gnss_ros import io as bagio

#: Topics left out unless asked for.
DEFAULT_SKIP = ("/diagnostics",)


@dataclass
class TopicComparison:
    """Counts of one topic in both bags and the first difference (None: identical)."""

    topic: str
    count_a: int
    count_b: int
    first_difference: str | None = None

    @property
    def identical(self) -> bool:
        return self.first_difference is None and self.count_a == self.count_b


@dataclass
class Comparison:
    topics: list = field(default_factory=list)

    @property
    def identical(self) -> bool:
        return all(t.identical for t in self.topics)

    def lines(self) -> list:
        out = []
        for t in self.topics:
            verdict = "identical" if t.identical else (t.first_difference or "counts differ")
            out.append(f"{t.topic}: {t.count_a} / {t.count_b} messages, {verdict}")
        out.append("IDENTICAL" if self.identical else "DIFFERENT")
        return out


def _output_bag(path) -> Path:
    """A replay folder's ``bag`` or a bag folder itself."""
    path = Path(path)
    return path / "bag" if (path / "bag").is_dir() else path


def compare(a, b, skip=DEFAULT_SKIP) -> Comparison:
    """Compare the output bags of replay folders (or bag folders) a and b."""
    bag_a, bag_b = _output_bag(a), _output_bag(b)
    topics_a, topics_b = bagio.bag_topics(bag_a), bagio.bag_topics(bag_b)
    result = Comparison()
    for topic in sorted((set(topics_a) | set(topics_b)) - set(skip)):
        msgs_a = bagio.read_bag(bag_a, [topic]) if topic in topics_a else []
        msgs_b = bagio.read_bag(bag_b, [topic]) if topic in topics_b else []
        entry = TopicComparison(topic, len(msgs_a), len(msgs_b))
        for k, (x, y) in enumerate(zip(msgs_a, msgs_b)):
            diff = (f"log time {x.t_ns} vs {y.t_ns}" if x.t_ns != y.t_ns
                    else bagio.first_difference(x.msg, y.msg))
            if diff is not None:
                entry.first_difference = f"message {k}: {diff}"
                break
        result.topics.append(entry)
    return result
