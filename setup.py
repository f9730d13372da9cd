# The Python package (python/active_tensegrity) for catkin_python_setup(); the compiled part, _core, is built
# by CMakeLists.txt into the same package folder of the devel and install spaces.
from setuptools import setup

from catkin_pkg.python_setup import generate_distutils_setup

setup(**generate_distutils_setup(packages=["active_tensegrity"], package_dir={"": "python"}))
