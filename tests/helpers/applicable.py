"""The filters that apply to each plant (importable: pytest's ``pythonpath`` has this folder).

Linear-only filters need a LinearModel (CarrierMotion), continuous ones a
``continuous_model`` (CarrierMotion, VanDerPol). The FIR smoother estimates ``x(k-N+1)``,
not the current state, so it is no controller's observation and is placed nowhere.
"""

APPLICABLE: dict[str, list[str]] = {
    "fir_gym/Orbit-v0": ["ekf", "ukf", "lkf", "efir"],
    "fir_gym/UncertainOscillator-v0": ["ekf", "ukf", "lkf", "efir"],
    "fir_gym/CarrierMotion-v0": ["kf", "ekf", "ukf", "lkf", "efir", "fir", "ufir", "rfir",
                                 "cd-ekf", "bpf-kf"],
    "fir_gym/VanDerPol-v0": ["ekf", "ukf", "lkf", "efir", "cd-ekf", "bpf-kf"],
    "fir_gym/PendulumSlider-v0": ["ekf", "ukf", "lkf", "efir"],
}
