"""Whether a COLLADA file is in the course's dialect, the only COLLADA ptrace reads.

The course's files place every node by one <matrix>, instance nothing but geometry, lights
and cameras, and each has a camera (the course's camera rule starts from it). A file from any
other exporter (Blender, 3ds Max, Maya, SketchUp, assimp's test models) breaks these rules in
ways the course's reader would read wrongly, so it is refused, with what was found, before the
course's reader starts.

Why not read such files another way: trimesh's COLLADA reader (through pycollada) was tried on
assimp's 25 COLLADA test models and read no triangles at all from three of them that hold
geometry (teapots.DAE, earthCylindrical.DAE, cube_emptyTags.dae) without an error, and it
ignores <up_axis> and <unit>: silently wrong images. Converting the file to
glTF (Blender, or `assimp export model.dae model.glb`) keeps what it means.
"""
TRANSFORMS = ("translate", "rotate", "scale", "lookat", "skew")


def check_dialect(document):
    """Refuse (document.fail) a file that is not in the course's dialect, naming the first
    element that is not and every other kind of departure found."""
    found, first = [], None
    for node in document.root.iter("node"):
        for child in node:
            tag = child.tag if isinstance(child.tag, str) else ""
            if tag in TRANSFORMS or tag == "instance_node":
                kind = f"<{tag}>"
                if first is None:
                    only = " (only <matrix>)" if tag in TRANSFORMS else ""
                    first = (f"{document.describe(node)} uses {kind}, which the course's "
                             f"reader does not support{only}")
                if kind not in found:
                    found.append(kind)
    has_camera = next(document.root.iter("instance_camera"), None) is not None
    if first is None and has_camera:
        return
    extras = [f"also uses {', '.join(found[1:])}"] if found[1:] else []
    if first is None:
        first = ("it has no camera (each of the course's files has one; its camera rule "
                 "starts from it)")
    elif not has_camera:
        extras.append("has no camera")
    also = f"; it {' and '.join(extras)}" if extras else ""
    document.fail(f"is COLLADA but not in the course's dialect, the only COLLADA ptrace "
                  f"reads: {first}{also}. Convert it to glTF (.glb), e.g. with Blender or "
                  f"`assimp export`, to render it")
