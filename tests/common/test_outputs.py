"""The checks every command makes of its files before any work (:func:`etmpc.common.outputs.check_outputs`): a
file it writes inside its output directory is checked against what it reads; a file it edits in place (a README)
is an input no other output may land on, though it may lie in the output directory; a path that is no regular
file (a FIFO, a device) is refused, as an input or an output, and never opened."""

import os
import signal

import pytest

from etmpc.common.documents import read_document
from etmpc.common.errors import EtmpcError
from etmpc.common.outputs import check_outputs

PAGE = ("page.md", "page.json")


def test_a_file_written_in_the_directory_is_refused_when_it_is_an_input(tmp_path):
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "page.json").write_text("{}")
    with pytest.raises(EtmpcError, match=r"--out .*out would write over the --card it reads \(.*page.json\)"):
        check_outputs({}, {"--out": tmp_path / "out"}, {"--card": tmp_path / "out" / "page.json"}, {"--out": PAGE})
    check_outputs({}, {"--out": tmp_path / "out"}, {"--card": tmp_path / "out" / "other.json"}, {"--out": PAGE})


def test_an_edited_file_is_refused_under_an_output_and_taken_elsewhere_in_the_directory(tmp_path):
    (tmp_path / "out").mkdir()
    for name in ("page.md", "README.md"):
        (tmp_path / "out" / name).write_text("# mine\n")
    directory = {"--out": tmp_path / "out"}
    with pytest.raises(EtmpcError, match="would write over the --readme it edits"):
        check_outputs({}, directory, writes={"--out": PAGE}, edits={"--readme": tmp_path / "out" / "page.md"})
    check_outputs({}, directory, writes={"--out": PAGE}, edits={"--readme": tmp_path / "out" / "README.md"})
    with pytest.raises(EtmpcError, match="would overwrite the --readme it edits"):
        check_outputs({"--json": tmp_path / "R.md"}, edits={"--readme": tmp_path / "R.md"})


def test_a_test_of_names_claims_every_file_beneath_what_it_claims(tmp_path):
    (tmp_path / "run" / "seed0").mkdir(parents=True)
    (tmp_path / "run" / "seed0" / "mine.yml").write_text("a: 1\n")
    owns = {"--out": lambda name: name.startswith("seed")}
    with pytest.raises(EtmpcError, match="would write over the --settings it reads"):
        check_outputs({}, {"--out": tmp_path / "run"}, {"--settings": tmp_path / "run" / "seed0" / "mine.yml"}, owns)
    os.mkfifo(tmp_path / "run" / "seed0" / "state.json")
    with pytest.raises(EtmpcError, match=r"holds .*state.json, a FIFO \(named pipe\), where it writes a file"):
        check_outputs({}, {"--out": tmp_path / "run"}, writes=owns)


@pytest.mark.parametrize("kind", ["fifo", "directory"])
def test_a_named_file_in_the_directory_that_is_no_regular_file_is_refused(kind, tmp_path):
    (tmp_path / "out").mkdir()
    os.mkfifo(tmp_path / "out" / "page.md") if kind == "fifo" else (tmp_path / "out" / "page.md").mkdir()
    with pytest.raises(EtmpcError, match="page.md, a (FIFO|directory)"):
        check_outputs({}, {"--out": tmp_path / "out"}, writes={"--out": PAGE})


def test_an_input_or_output_that_is_no_regular_file_is_refused_and_never_opened(tmp_path):
    os.mkfifo(tmp_path / "fifo")
    with pytest.raises(EtmpcError, match=r"fifo \(--settings\) is a FIFO \(named pipe\), not a regular file"):
        check_outputs({}, inputs={"--settings": tmp_path / "fifo"})
    with pytest.raises(EtmpcError, match=r"fifo \(--readme\) is a FIFO"):
        check_outputs({}, edits={"--readme": tmp_path / "fifo"})
    with pytest.raises(EtmpcError, match="--json .*fifo is a FIFO"):
        check_outputs({"--json": tmp_path / "fifo"})
    with pytest.raises(EtmpcError, match="--out .*fifo is a FIFO .*, not a directory"):
        check_outputs({}, {"--out": tmp_path / "fifo"})
    with pytest.raises(EtmpcError, match="--json /dev/null is a character device"):
        check_outputs({"--json": "/dev/null"})
    with pytest.raises(EtmpcError, match=r"/dev/null \(test set\) is a character device"):
        check_outputs({}, inputs={"test set": "/dev/null"})
    with pytest.raises(EtmpcError, match=r"\(--card\) is a directory, not a regular file"):
        check_outputs({}, inputs={"--card": tmp_path})


def test_the_shared_reader_refuses_a_fifo_without_opening_it(tmp_path):
    path = tmp_path / "card.json"
    os.mkfifo(path)
    unreadable = f"card {path} cannot be read ({{error}})"

    def hung(signum, frame):  # opening it would wait for a writer that never comes
        raise AssertionError("the reader opened the FIFO")

    previous = signal.signal(signal.SIGALRM, hung)
    signal.alarm(10)
    try:
        with pytest.raises(EtmpcError, match=r"cannot be read \(it is a FIFO \(named pipe\), not a regular file\)"):
            read_document(path, "etmpc-scorecard", missing="missing", unreadable=unreadable, foreign="foreign")
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)
