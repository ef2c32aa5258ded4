"""vic.read_mcap of a real board recording against the client's reading of the same file
(vic_client.load_mcap, through the `mcap` package's reader): every channel, every column, every
value equal (a null, a non-finite number the board wrote, is NaN in both). Run by
tests/python_client.rs with the board's MCAP record, when the wheel is installed:

    python board_recording.py RECORD.mcap

Prints one line per check and `N passed, N failed`; exits 1 when a check failed.
"""

import sys

import numpy as np

import vic
import vic_client as vc


def main(path):
    ours = vic.read_mcap(path, pandas=False)
    theirs = vc.load_mcap(path)
    passed, failed = 0, 0
    # Keys that start with "_" describe the file (its metadata, whether it was read to its
    # end), not a channel; the recording was closed, so the client must have read all of it.
    if theirs.get("_complete") is False:
        print("FAIL the client read the closed recording only in part")
        sys.exit(1)
    topics = [t for t in theirs if not t.startswith("_")]
    for topic in topics:
        cols, ref = ours[topic], theirs[topic]
        problems = []
        values = 0
        if not np.array_equal(cols["log_time"], ref["_log_time_ns"]):
            problems.append("log_time")
        for key, want in ref.items():
            if key == "_log_time_ns":
                continue
            got = cols.get(key)
            if got is None:
                problems.append(f"{key} missing")
                continue
            if want.dtype == object:
                want = np.array([[np.nan if v is None else v for v in row] for row in want]) \
                    if want.ndim == 2 or isinstance(want[0], list) else want
            try:
                same = np.array_equal(np.asarray(got, dtype=float), np.asarray(want, dtype=float),
                                      equal_nan=True) and np.array_equal(got.shape, want.shape)
            except (TypeError, ValueError):
                same = list(got) == list(want)
            if not same:
                problems.append(key)
            values += np.size(want)
        if problems:
            failed += 1
            print(f"FAIL {topic}: {', '.join(problems)}")
        else:
            passed += 1
            print(f"ok   {topic}: {len(cols['log_time'])} messages, {values} values equal")
    if not topics:
        failed += 1
        print("FAIL no channel in the recording")
    print(f"{passed} passed, {failed} failed")
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    main(sys.argv[1])
