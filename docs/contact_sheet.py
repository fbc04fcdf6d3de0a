#!/usr/bin/env python3
"""Contact sheet of PNG frames (standard library only): each frame halved
(2x2 box filter), laid out COLS across with 4 px gaps.

    python3 docs/contact_sheet.py OUT.png COLS frame0.png frame1.png ...
"""
import struct
import sys
import zlib


def read_png(path):
    """8-bit RGB or RGBA, non-interlaced PNG -> (width, height, rgb bytes)."""
    data = open(path, "rb").read()
    pos, idat = 8, b""
    while pos < len(data):
        (length,) = struct.unpack(">I", data[pos : pos + 4])
        kind, body = data[pos + 4 : pos + 8], data[pos + 8 : pos + 8 + length]
        pos += 12 + length
        if kind == b"IHDR":
            width, height, depth, colour = struct.unpack(">IIBB", body[:10])
            assert depth == 8 and colour in (2, 6), f"{path}: unsupported PNG"
        elif kind == b"IDAT":
            idat += body
    raw, bpp = zlib.decompress(idat), {2: 3, 6: 4}[colour]
    stride, prev, out, i = width * bpp, bytearray(width * bpp), bytearray(), 0
    for _ in range(height):
        kind, line = raw[i], bytearray(raw[i + 1 : i + 1 + stride])
        i += 1 + stride
        for x in range(stride):
            a = line[x - bpp] if x >= bpp else 0
            b, c = prev[x], (prev[x - bpp] if x >= bpp else 0)
            if kind == 1:
                line[x] = (line[x] + a) & 255
            elif kind == 2:
                line[x] = (line[x] + b) & 255
            elif kind == 3:
                line[x] = (line[x] + (a + b) // 2) & 255
            elif kind == 4:
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                line[x] = (line[x] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 255
        out += line if bpp == 3 else bytes(v for k, v in enumerate(line) if k % 4 != 3)
        prev = line
    return width, height, out


def write_png(path, width, height, rgb):
    raw = b"".join(b"\x00" + bytes(rgb[y * width * 3 : (y + 1) * width * 3]) for y in range(height))

    def chunk(kind, body):
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))

    header = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    open(path, "wb").write(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b""))


def main():
    out, cols, paths = sys.argv[1], int(sys.argv[2]), sys.argv[3:]
    frames = [read_png(p) for p in paths]
    w, h = frames[0][0] // 2, frames[0][1] // 2
    rows, gap = (len(frames) + cols - 1) // cols, 4
    sheet_w, sheet_h = cols * w + (cols - 1) * gap, rows * h + (rows - 1) * gap
    sheet = bytearray(sheet_w * sheet_h * 3)
    for n, (fw, _, rgb) in enumerate(frames):
        ox, oy = (n % cols) * (w + gap), (n // cols) * (h + gap)
        for y in range(h):
            for x in range(w):
                for ch in range(3):
                    s = sum(rgb[((2 * y + dy) * fw + 2 * x + dx) * 3 + ch] for dy in (0, 1) for dx in (0, 1))
                    sheet[((oy + y) * sheet_w + ox + x) * 3 + ch] = s // 4
    write_png(out, sheet_w, sheet_h, sheet)


if __name__ == "__main__":
    main()
