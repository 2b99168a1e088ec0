"""What C libraries print on their own (OpenImageIO's assertions, libpng's `libpng error: ...`
lines), kept off the user's terminal and folded into ptrace's one line.

Such libraries write to file descriptor 2 directly, past Python's sys.stderr, so the capture is
of the descriptor: while a block runs, descriptor 2 is a temporary file, and what landed there
is the block's `text` afterwards, for the caller to fold into its error or note (one_line).
"""
import contextlib
import os
import sys
import tempfile


class Captured:
    """What a library printed during a `library_output()` block (its `text`, "" if nothing)."""
    text = ""

    def one_line(self, *messages):
        """The messages and the captured text as one line: their lines, each once, in order,
        without the libraries' own prefixes, joined by '; ' ("" if there is nothing)."""
        return one_line(*messages, self.text)


def one_line(*texts):
    """The lines of texts, each once, in order, without a library's prefix ("libpng error:
    ", "libpng warning: ") and without those another line holds whole, joined by '; '."""
    seen = []
    for text in texts:
        for line in str(text or "").splitlines():
            line = line.strip()
            for prefix in ("libpng error:", "libpng warning:"):
                if line.startswith(prefix):
                    line = line[len(prefix):].strip()
            if line and line not in seen:
                seen.append(line)
    # a line another one repeats in full ("Read error: ..." in "PNG read error: IDAT: Read
    # error: ...") says nothing more
    return "; ".join(line for line in seen
                     if not any(line != other and line in other for other in seen))


@contextlib.contextmanager
def library_output():
    """Run the block with file descriptor 2 captured (a Captured, whose text is set when the
    block ends); where the descriptor cannot be redirected the block runs as it is."""
    captured = Captured()
    try:
        sys.stderr.flush()
    except (AttributeError, OSError, ValueError):
        pass
    try:
        saved = os.dup(2)
        sink = tempfile.TemporaryFile()
    except OSError:
        yield captured
        return
    try:
        os.dup2(sink.fileno(), 2)
        try:
            yield captured
        finally:
            try:
                sys.stderr.flush()
            except (AttributeError, OSError, ValueError):
                pass
            os.dup2(saved, 2)
            sink.seek(0)
            captured.text = sink.read(1 << 16).decode("utf-8", "replace")
    finally:
        os.close(saved)
        sink.close()
