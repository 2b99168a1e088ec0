"""A seeded generator of malformed scene files, each broken in a way the loader must refuse.

Every case is built from a valid scene by one mutation that cannot leave it valid (numbers are
corrupted only where the loader reads them: positions, node matrices, VERTEX indices, urls that
are followed). The corpus is generated at test time; no file of it is committed.
"""
import random
import re

ENTITY_BOMB = """<?xml version="1.0"?>
<!DOCTYPE lolz [<!ENTITY lol "lol">\
<!ENTITY lol2 "&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;">
<!ENTITY lol3 "&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;">
<!ENTITY lol4 "&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;">
<!ENTITY lol5 "&lol4;&lol4;&lol4;&lol4;&lol4;&lol4;&lol4;&lol4;&lol4;&lol4;">
<!ENTITY lol6 "&lol5;&lol5;&lol5;&lol5;&lol5;&lol5;&lol5;&lol5;&lol5;&lol5;">
<!ENTITY lol7 "&lol6;&lol6;&lol6;&lol6;&lol6;&lol6;&lol6;&lol6;&lol6;&lol6;">
<!ENTITY lol8 "&lol7;&lol7;&lol7;&lol7;&lol7;&lol7;&lol7;&lol7;&lol7;&lol7;">
<!ENTITY lol9 "&lol8;&lol8;&lol8;&lol8;&lol8;&lol8;&lol8;&lol8;&lol8;&lol8;">]>
<COLLADA><asset><up_axis>Y_UP</up_axis></asset><library_geometries>&lol9;</library_geometries></COLLADA>
"""

EXTERNAL_ENTITY = """<?xml version="1.0"?>
<!DOCTYPE c [<!ENTITY secret SYSTEM "file:///etc/passwd">]>
<COLLADA><asset><up_axis>Y_UP</up_axis><contributor>&secret;</contributor></asset></COLLADA>
"""


def _replace_nth(text, pattern, n, replacement):
    matches = list(re.finditer(pattern, text))
    match = matches[n % len(matches)]
    return text[:match.start()] + replacement(match) + text[match.end():]


def truncated(text, rng):
    end = text.rindex("</COLLADA>")
    return text[:rng.randrange(0, end)]


def lying_count(text, rng):
    pattern = r'(<float_array id="[^"]*positions-array" count=")(\d+)(")'
    n = rng.randrange(100)
    return _replace_nth(text, pattern, n, lambda m: m.group(1) + str(int(m.group(2)) +
                        rng.choice([1, 3, 1000, 2_000_000_000])) + m.group(3))


def huge_count(text, rng):
    pattern = r'(<float_array id="[^"]*positions-array" count=")(\d+)(")'
    return _replace_nth(text, pattern, rng.randrange(100),
                        lambda m: m.group(1) + "2000000000" + m.group(3))


def bad_number(text, rng):
    value = rng.choice(["nan", "NaN", "inf", "-inf", "1e999", "abc"])
    where = rng.choice(["positions", "matrix"])
    if where == "positions":
        pattern = r'(<float_array id="[^"]*positions-array" count="\d+">)([^<]*)(<)'
    else:
        pattern = r'(<matrix[^>]*>)([^<]*)(<)'

    def corrupt(m):
        numbers = m.group(2).split()
        numbers[rng.randrange(len(numbers))] = value
        return m.group(1) + " ".join(numbers) + m.group(3)
    return _replace_nth(text, pattern, rng.randrange(100), corrupt)


def index_out_of_range(text, rng):
    def corrupt(m):
        numbers = m.group(2).split()
        numbers[0] = rng.choice(["1000000", "-1", "99999999999999999999"])   # VERTEX at offset 0
        return m.group(1) + " ".join(numbers) + m.group(3)
    return _replace_nth(text, r"(<p>)([^<]*)(</p>)", rng.randrange(100), corrupt)


def missing_id(text, rng):
    pattern = (r'((?:instance_geometry|instance_light|instance_camera|instance_effect) '
               r'url="#)([^"]+)(")')
    material_pattern = r'(<instance_material symbol="[^"]*" target="#)([^"]+)(")'
    if rng.random() < 0.3 and re.search(material_pattern, text):
        pattern = material_pattern
    return _replace_nth(text, pattern, rng.randrange(100),
                        lambda m: m.group(1) + "missing-" + m.group(2) + m.group(3))


def deeply_nested(text, rng):
    depth = rng.choice([1000, 20000, 100000])
    opening = '<node id="n" type="NODE">' * depth
    closing = "</node>" * depth
    return text.replace("</visual_scene>", opening + closing + "</visual_scene>", 1)


def not_collada(text, rng):
    return rng.choice(["", "not xml at all", "<html><body>hello</body></html>",
                       '<?xml version="1.0"?><COLLADA></COLLADA>',
                       text.replace("<up_axis>", "<up_axis_missing>").replace(
                           "</up_axis>", "</up_axis_missing>")])


MUTATIONS = [(truncated, 60), (lying_count, 25), (huge_count, 10), (bad_number, 35),
             (index_out_of_range, 25), (missing_id, 26), (deeply_nested, 6), (not_collada, 12)]


def corpus(base_texts, seed=0):
    """[(name, text)]: every mutation applied to seeded choices of the base scenes."""
    rng = random.Random(seed)
    cases = [("entity-bomb", ENTITY_BOMB), ("external-entity", EXTERNAL_ENTITY)]
    for mutation, count in MUTATIONS:
        for i in range(count):
            base_name, base = rng.choice(base_texts)
            cases.append((f"{mutation.__name__}-{i}-{base_name}", mutation(base, rng)))
    return cases
