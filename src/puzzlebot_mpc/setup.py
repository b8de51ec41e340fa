from catkin_pkg.python_setup import generate_distutils_setup
from setuptools import setup

setup(**generate_distutils_setup(packages=["puzzlebot_mpc", "puzzlebot_mpc.behaviors"], package_dir={"": "src"}))
