"""A parsed COLLADA file: safe XML reading, the id table, url lookup and number parsing.

Every problem is raised as a SceneError that names the file and the element at fault.
"""
import os

# The files are untrusted input. defusedxml refuses entity declarations (billion-laughs bombs)
# and external entities / DTD fetches, which the standard library parser would expand or follow.
# pycollada is not used: it does not read the course's CGL <extra> extensions.
import defusedxml
import defusedxml.ElementTree as safe_xml
import numpy as np

from ..errors import SceneError

FLOAT = np.float64
INDEX = np.int64


def local_tag(tag):
    """'{namespace}node' -> 'node'."""
    return tag.rsplit("}", 1)[-1] if tag.startswith("{") else tag


class ColladaDocument:
    """The element tree of one file with ids, parents and helpers that report errors."""

    def __init__(self, path):
        self.path = str(path)
        self.notes = []
        self.root = self._parse(self._read_bytes())
        self.parents = {}
        self.ids = {}
        duplicate_ids = 0
        for element in self.root.iter():
            if not isinstance(element.tag, str):      # comments, processing instructions
                continue
            element.tag = local_tag(element.tag)
            for child in element:
                self.parents[child] = element
            element_id = element.get("id")
            if element_id is not None:
                if element_id in self.ids:
                    duplicate_ids += 1          # the first element with an id wins
                else:
                    self.ids[element_id] = element
        if duplicate_ids:
            self.notes.append(f"{duplicate_ids} duplicate id(s); the first element with each id "
                              "is used")
        if self.root.tag != "COLLADA":
            self.fail(f"not a COLLADA file: the root element is <{self.root.tag}>")

    # --- reading -------------------------------------------------------------------------

    def _read_bytes(self):
        if not os.path.exists(self.path):
            self.fail("no such file")
        if os.path.isdir(self.path):
            self.fail("is a directory, not a scene file")
        try:
            with open(self.path, "rb") as stream:
                return stream.read()
        except OSError as error:
            self.fail(f"cannot read the file: {error.strerror or error}")

    def _parse(self, data):
        try:
            return safe_xml.fromstring(data)
        except defusedxml.DefusedXmlException as error:
            self.fail(f"refused unsafe XML ({type(error).__name__}: entity declarations, "
                      f"DTDs fetching external resources and external references are not allowed)")
        except safe_xml.ParseError as error:
            self.fail(f"not well-formed XML: {error}")
        except (LookupError, ValueError, UnicodeError) as error:
            self.fail(f"not readable as XML: {error}")

    # --- errors --------------------------------------------------------------------------

    def fail(self, message):
        raise SceneError(self.path, message)

    def describe(self, element):
        """'<polylist> in <geometry id="x">': the element and its nearest ancestor with an id."""
        text = self._tag_text(element)
        if element.get("id") is None:
            ancestor = self.parents.get(element)
            while ancestor is not None and ancestor.get("id") is None:
                ancestor = self.parents.get(ancestor)
            if ancestor is not None:
                text += f" in {self._tag_text(ancestor)}"
        return text

    @staticmethod
    def _tag_text(element):
        for key in ("id", "sid", "name"):
            if element.get(key) is not None:
                return f'<{element.tag} {key}="{element.get(key)}">'
        return f"<{element.tag}>"

    # --- structure -----------------------------------------------------------------------

    def child(self, element, tag):
        """The first child with this tag, or None."""
        for child in element:
            if child.tag == tag:
                return child
        return None

    def children(self, element, tag):
        return [child for child in element if child.tag == tag]

    def require_child(self, element, tag):
        found = self.child(element, tag)
        if found is None:
            self.fail(f"{self.describe(element)} has no <{tag}>")
        return found

    def find_path(self, element, *tags):
        """Follow first children with these tags; None if any step is missing."""
        for tag in tags:
            if element is None:
                return None
            element = self.child(element, tag)
        return element

    def resolve(self, element, attribute, expected_tags=None):
        """The element named by element's '#id' attribute (url, target, source)."""
        reference = element.get(attribute)
        if reference is None:
            self.fail(f"{self.describe(element)} has no {attribute} attribute")
        if not reference.startswith("#"):
            self.fail(f'{self.describe(element)} {attribute}="{reference}": only references '
                      f'to this file ("#id") are supported')
        target = self.ids.get(reference[1:])
        if target is None:
            self.fail(f'{self.describe(element)} {attribute}="{reference}": '
                      f'no element has id "{reference[1:]}"')
        if expected_tags is not None and target.tag not in expected_tags:
            wanted = " or ".join(f"<{tag}>" for tag in expected_tags)
            self.fail(f'{self.describe(element)} {attribute}="{reference}" names a '
                      f"<{target.tag}>, expected {wanted}")
        return target

    # --- numbers -------------------------------------------------------------------------

    def floats(self, element, what="numbers"):
        """All whitespace-separated numbers in element's text; NaN or infinity is an error."""
        values = self._numbers(element, FLOAT, what)
        if values.size and not np.isfinite(values).all():
            self.fail(f"{self.describe(element)}: NaN or infinite {what}")
        return values

    def indices(self, element, what="indices"):
        """Whitespace-separated non-negative integers in element's text."""
        values = self._numbers(element, INDEX, what)
        if values.size and values.min() < 0:
            self.fail(f"{self.describe(element)}: negative {what} ({int(values.min())})")
        return values

    def _numbers(self, element, dtype, what):
        words = (element.text or "").split()
        try:
            return np.array(words, dtype=dtype)
        except (ValueError, OverflowError, TypeError):
            bad = next((word for word in words if not _is_number(word, dtype)), "?")
            kind = "an integer" if dtype is INDEX else "a number"
            self.fail(f'{self.describe(element)}: "{bad[:40]}" in the {what} is not {kind}')

    def vector(self, element, size, what):
        """Exactly the first `size` numbers of element's text (more are ignored, e.g. alpha)."""
        values = self.floats(element, what)
        if values.size < size:
            self.fail(f"{self.describe(element)}: {what} needs {size} numbers, "
                      f"found {values.size}")
        return values[:size]

    def scalar(self, element, what):
        return float(self.vector(element, 1, what)[0])

    def count_attribute(self, element, attribute="count"):
        """A non-negative integer attribute, or None if absent."""
        text = element.get(attribute)
        if text is None:
            return None
        try:
            value = int(text.strip())
        except ValueError:      # also a number with more digits than Python converts
            self.fail(f'{self.describe(element)}: {attribute}="{text[:40]}" is not an integer')
        if value < 0:
            self.fail(f'{self.describe(element)}: {attribute}="{text}" is negative')
        if value >= 2**62:
            self.fail(f'{self.describe(element)}: {attribute}="{text[:40]}" is too large')
        return value


def _is_number(word, dtype):
    try:
        value = int(word) if dtype is INDEX else float(word)
    except (ValueError, OverflowError):
        return False
    return dtype is not INDEX or -2**63 <= value < 2**63
