"""Observers: filters, smoothers, identification and metrics. Import models/, never fmus/."""
