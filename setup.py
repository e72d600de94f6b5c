"""ament_python set-up of cvc_balance (colcon build, pip install)."""

from glob import glob

from setuptools import find_packages, setup

PACKAGE = 'cvc_balance'

setup(
    name=PACKAGE,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    package_data={'cvc_balance.study': ['bench_references.json']},
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + PACKAGE]),
        ('share/' + PACKAGE, ['package.xml']),
        ('share/' + PACKAGE + '/config', glob('config/*.yaml')),
        ('share/' + PACKAGE + '/bags', glob('bags/*.mcap') + glob('bags/*.yaml')),
    ],
    python_requires='>=3.11',
    install_requires=['setuptools', 'numpy', 'PyYAML', 'msgspec'],
    extras_require={'test': ['pytest']},
    zip_safe=True,
    maintainer='cvc_balance developers',
    maintainer_email='dev@cvc-balance.invalid',
    description='Bearing loads, drive torque and unbalance of a single-axis rotor (CVC).',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            'cvc-balance = cvc_balance.cli:main',
            'balance-monitor = cvc_balance.ros.balance_monitor:main',
            'balance_monitor = cvc_balance.ros.balance_monitor:main',
        ],
    },
)
