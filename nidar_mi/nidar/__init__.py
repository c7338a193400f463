"""nidar"""
