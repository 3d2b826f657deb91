#!/usr/bin/python3
"""OpenCV's own Python bindings on a chessboard folder, with the flags workbench uses:
classic detector (ADAPTIVE_THRESH | NORMALIZE_IMAGE | FAST_CHECK) + cornerSubPix with a half
window of a third of the corner spacing (3..25 px), calibrateCamera with k3 fixed.
Prints one JSON line. Usage: cv2_calibrate.py DIR COLS ROWS SQUARE_MM"""
import json, os, sys, time
import cv2
import numpy as np

d, cols, rows, sq = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), float(sys.argv[4])
files = sorted(f for f in os.listdir(d) if f.lower().endswith((".jpg", ".jpeg", ".png", ".tif", ".tiff")))
obj = np.zeros((rows * cols, 3), np.float32)
obj[:, :2] = np.mgrid[0:cols, 0:rows].T.reshape(-1, 2) * sq
t0 = time.time()
objs, imgs, size = [], [], None
for f in files:
    g = cv2.imread(os.path.join(d, f), cv2.IMREAD_GRAYSCALE)
    size = g.shape[::-1]
    s = min(1.0, 1600.0 / max(g.shape))
    small = g if s == 1.0 else cv2.resize(g, None, fx=s, fy=s, interpolation=cv2.INTER_AREA)
    ok, c = cv2.findChessboardCorners(small, (cols, rows), flags=cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_FAST_CHECK)
    if not ok:
        continue
    c = (c / s).astype(np.float32)
    p = c.reshape(rows, cols, 2)
    spacing = min(np.linalg.norm(np.diff(p, axis=1), axis=2).min(), np.linalg.norm(np.diff(p, axis=0), axis=2).min())
    w = int(round(min(max(spacing / 3.0, 3.0), 25.0)))
    c = cv2.cornerSubPix(g, c, (w, w), (-1, -1), (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 60, 1e-4))
    objs.append(obj)
    imgs.append(c)
t1 = time.time()
rms, k, dist, rv, tv = cv2.calibrateCamera(objs, imgs, size, None, None, flags=cv2.CALIB_FIX_K3,
                                           criteria=(cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 100, 1e-12))
t2 = time.time()
print(json.dumps({"views": len(imgs), "fx": k[0, 0], "fy": k[1, 1], "cx": k[0, 2], "cy": k[1, 2],
                  "k1": float(dist.ravel()[0]), "k2": float(dist.ravel()[1]), "rms": rms,
                  "detect_s": t1 - t0, "calibrate_s": t2 - t1, "threads": cv2.getNumThreads()}))
