"""The BlueBot: dynamics, vision, controllers (pure numpy) and hardware drivers."""
