"""glMemoryBarrier bits and the rule that derives them from how a resource was written and
how it is used next.

A barrier is needed only after an incoherent write: an image store (``imageStore``,
image atomics) or a shader-storage write (SSBO stores, atomics). Writes through a
framebuffer, uploads, clears and copies are ordered by GL itself. The bit to issue names
the *next* access (GL 4.6, 7.13.2): a texture fetch needs ``TEXTURE_FETCH``, an image load
or store ``SHADER_IMAGE_ACCESS``, drawing into or clearing an attachment ``FRAMEBUFFER``,
an upload or read-back of a texture ``TEXTURE_UPDATE``, and so on.

Write accesses: ``image``, ``storage`` (incoherent), ``framebuffer``, ``upload`` (including
clears), ``host`` (a Python object). Read accesses: ``texture``, ``image``, ``storage``,
``uniform``, ``vertex``, ``index``, ``indirect``, ``framebuffer`` (blending, depth test
against an attachment), ``readback``, ``host``.
"""
from __future__ import annotations

VERTEX_ATTRIB_ARRAY_BARRIER_BIT = 0x0001
ELEMENT_ARRAY_BARRIER_BIT = 0x0002
UNIFORM_BARRIER_BIT = 0x0004
TEXTURE_FETCH_BARRIER_BIT = 0x0008
SHADER_IMAGE_ACCESS_BARRIER_BIT = 0x0020
COMMAND_BARRIER_BIT = 0x0040
PIXEL_BUFFER_BARRIER_BIT = 0x0080
TEXTURE_UPDATE_BARRIER_BIT = 0x0100
BUFFER_UPDATE_BARRIER_BIT = 0x0200
FRAMEBUFFER_BARRIER_BIT = 0x0400
SHADER_STORAGE_BARRIER_BIT = 0x2000
ALL_BARRIER_BITS = 0xFFFFFFFF

BARRIER_NAMES = {
    VERTEX_ATTRIB_ARRAY_BARRIER_BIT: "VERTEX_ATTRIB_ARRAY", ELEMENT_ARRAY_BARRIER_BIT: "ELEMENT_ARRAY",
    UNIFORM_BARRIER_BIT: "UNIFORM", TEXTURE_FETCH_BARRIER_BIT: "TEXTURE_FETCH",
    SHADER_IMAGE_ACCESS_BARRIER_BIT: "SHADER_IMAGE_ACCESS", COMMAND_BARRIER_BIT: "COMMAND",
    PIXEL_BUFFER_BARRIER_BIT: "PIXEL_BUFFER", TEXTURE_UPDATE_BARRIER_BIT: "TEXTURE_UPDATE",
    BUFFER_UPDATE_BARRIER_BIT: "BUFFER_UPDATE", FRAMEBUFFER_BARRIER_BIT: "FRAMEBUFFER",
    SHADER_STORAGE_BARRIER_BIT: "SHADER_STORAGE",
}

# shader stages read a texture both ways in this renderer (a sampler here, imageLoad there)
TEXTURE_READ_BITS = TEXTURE_FETCH_BARRIER_BIT | SHADER_IMAGE_ACCESS_BARRIER_BIT
BUFFER_READ_BITS = (SHADER_STORAGE_BARRIER_BIT | UNIFORM_BARRIER_BIT | VERTEX_ATTRIB_ARRAY_BARRIER_BIT
                    | ELEMENT_ARRAY_BARRIER_BIT | COMMAND_BARRIER_BIT)

INCOHERENT_WRITES = frozenset({"image", "storage"})
WRITE_ACCESSES = frozenset({"image", "storage", "framebuffer", "upload", "host"})
READ_ACCESSES = frozenset({"texture", "image", "storage", "uniform", "vertex", "index", "indirect",
                           "framebuffer", "readback", "host"})

WRITE_ACCESS_NAMES = {"image": "image store", "storage": "shader-storage write", "framebuffer": "framebuffer draw",
                      "upload": "upload/clear", "host": "host write"}
READ_ACCESS_NAMES = {"texture": "texture fetch", "image": "image load/store", "storage": "shader-storage access",
                     "uniform": "uniform-buffer read", "vertex": "vertex fetch", "index": "index fetch",
                     "indirect": "indirect command", "framebuffer": "framebuffer draw/clear",
                     "readback": "read-back", "upload": "upload/clear", "host": "host access"}

# the next access (a read, or a write that must come after) -> the bit that orders it after an
# incoherent write; for textures and buffers separately where GL names them differently
_NEXT_TEXTURE = {"texture": TEXTURE_FETCH_BARRIER_BIT, "image": SHADER_IMAGE_ACCESS_BARRIER_BIT,
                 "framebuffer": FRAMEBUFFER_BARRIER_BIT, "upload": TEXTURE_UPDATE_BARRIER_BIT,
                 "readback": TEXTURE_UPDATE_BARRIER_BIT, "host": 0}
_NEXT_BUFFER = {"storage": SHADER_STORAGE_BARRIER_BIT, "uniform": UNIFORM_BARRIER_BIT,
                "vertex": VERTEX_ATTRIB_ARRAY_BARRIER_BIT, "index": ELEMENT_ARRAY_BARRIER_BIT,
                "indirect": COMMAND_BARRIER_BIT, "texture": TEXTURE_FETCH_BARRIER_BIT,
                "image": SHADER_IMAGE_ACCESS_BARRIER_BIT, "upload": BUFFER_UPDATE_BARRIER_BIT,
                "readback": BUFFER_UPDATE_BARRIER_BIT, "framebuffer": 0, "host": 0}


def required_bits(written: str | None, next_access: str, is_buffer: bool) -> int:
    """Bits that make a write of kind ``written`` visible to ``next_access`` (0: none needed)."""
    if written not in INCOHERENT_WRITES:
        return 0
    table = _NEXT_BUFFER if is_buffer else _NEXT_TEXTURE
    return table.get(next_access, 0)


def barrier_names(bits: int) -> list[str]:
    return [n for b, n in BARRIER_NAMES.items() if bits & b]
