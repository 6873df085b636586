"""Makes the OpenCV Gray code fixture (issue 52: Sheen's Gray decoding
proven equal to OpenCV's on a full code).

OpenCV's own `structured_light.GrayCodePattern` generates the patterns of a
1920 x 1080 projector with one code per projector column and row (a full
code: 11 column and 11 row bit planes, each pattern then its inverse, 44
frames, OpenCV's order). A 320 x 240 camera sees a 160 x 120 projector
pixel patch through a perspective warp, with bilinear blur, a gain of 0.8
and a black level of 12 DN: `cap00.png` .. `cap43.png`, `white.png`,
`black.png`. OpenCV's own decoder (`getProjPixel`, its default thresholds,
and its shadow mask: white minus black above 40) decodes every camera pixel;
`opencv_x.png` and `opencv_y.png` (16-bit) hold the projector column and
row it found, 65535 where it found none; `camera_to_projector.json` the
warp (a camera pixel's centre to the projector's, pixel centres at integers).

Run from this folder with `pip install opencv-contrib-python-headless`
(made with OpenCV 5.1.0): `python3 make_fixture.py`.
"""

import json

import cv2
import numpy as np

PROJECTOR = (1920, 1080)
CAMERA = (320, 240)
BLACK_DN, GAIN = 12.0, 0.8

code = cv2.structured_light.GrayCodePattern.create(*PROJECTOR)
ok, patterns = code.generate()
assert ok and len(patterns) == 44 == code.getNumberOfPatternImages()

# Camera pixel corners -> projector pixels: a tilted view of a patch near
# the projector's centre (902..1062 x 478..598), so that edges of every
# bit plane, and the MSB's at 960 and 540, cross the image.
camera_corners = np.float32([[0, 0], [CAMERA[0], 0], [CAMERA[0], CAMERA[1]], [0, CAMERA[1]]])
projector_corners = np.float32([[902, 480], [1058, 478], [1062, 598], [899, 596]])
to_projector = cv2.getPerspectiveTransform(camera_corners, projector_corners)


def capture(image):
    seen = cv2.warpPerspective(
        image.astype(np.float32), to_projector, CAMERA,
        flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP)
    return np.clip(np.round(BLACK_DN + GAIN * seen), 0, 255).astype(np.uint8)


frames = [capture(p) for p in patterns]
white = capture(np.full(PROJECTOR[::-1], 255, np.uint8))
black = capture(np.zeros(PROJECTOR[::-1], np.uint8))
for i, f in enumerate(frames):
    cv2.imwrite(f"cap{i:02}.png", f)
cv2.imwrite("white.png", white)
cv2.imwrite("black.png", black)

decoded_x = np.full(CAMERA[::-1], 65535, np.uint16)
decoded_y = np.full(CAMERA[::-1], 65535, np.uint16)
for v in range(CAMERA[1]):
    for u in range(CAMERA[0]):
        if int(white[v, u]) - int(black[v, u]) <= 40:
            continue
        error, (x, y) = code.getProjPixel(frames, u, v)
        if not error:
            decoded_x[v, u], decoded_y[v, u] = x, y
with open("camera_to_projector.json", "w") as f:
    json.dump({"camera_to_projector": to_projector.tolist()}, f, indent=1)
cv2.imwrite("opencv_x.png", decoded_x)
cv2.imwrite("opencv_y.png", decoded_y)
print("OpenCV decoded", int((decoded_x != 65535).sum()), "of", CAMERA[0] * CAMERA[1], "pixels")
