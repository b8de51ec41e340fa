"""Robots counted from a screenshot's pixels (puzzlebot_bringup/screenshot.py robots_in_view); no rviz."""

from PIL import Image, ImageDraw

from puzzlebot_bringup.screenshot import robots_in_view

FLOOR = (48, 48, 48)
BODY = (51, 115, 217)          # the URDF's body blue as rviz shades it from above
PILOT = (242, 140, 26)
KNOB = (230, 230, 51)


def robot(draw, x, y, colour=BODY, side=70):
    """A robot seen from above: its body and, on its left (top of the picture), the knob sticking out."""
    draw.rectangle((x, y, x + side, y + side), fill=colour)
    draw.pieslice((x + side // 2 - 6, y - 6, x + side // 2 + 6, y + 6), 180, 360, fill=KNOB)


def picture():
    image = Image.new("RGB", (600, 400), FLOOR)
    return image, ImageDraw.Draw(image)


def test_each_robot_counted_once_also_when_bodies_touch():
    image, draw = picture()
    robot(draw, 50, 150)
    robot(draw, 200, 150, PILOT)
    for k in range(3):                  # a coupled chain: bodies touching
        robot(draw, 320 + 71 * k, 150)
    seen = robots_in_view(image)
    assert (seen.knobs, seen.cut) == (5, 0)


def test_yellow_that_is_not_a_knob_is_not_a_robot():
    image, draw = picture()
    robot(draw, 50, 150)
    draw.line((60, 190, 110, 200), fill=KNOB, width=4)          # a head-aligned pair's line on a body
    draw.rectangle((300, 40, 310, 48), fill=KNOB)               # yellow text of the legend, on the floor
    draw.rectangle((300, 60, 306, 64), fill=BODY)
    draw.rectangle((400, 250, 460, 256), fill=KNOB)             # a long yellow outline
    assert robots_in_view(image).knobs == 1


def test_a_robot_cut_by_the_edge_of_the_view():
    image, draw = picture()
    robot(draw, 50, 150)
    robot(draw, 560, 150)               # half out on the right
    seen = robots_in_view(image)
    assert seen.cut == 1 and seen.knobs == 2
    assert robots_in_view(image, box=(0, 0, 300, 400)).knobs == 1     # the box: only the view's pixels
