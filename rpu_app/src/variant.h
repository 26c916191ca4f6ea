/* SPDX-License-Identifier: MIT */
#ifndef RPU_VARIANT_H
#define RPU_VARIANT_H

extern const char rpu_variant[];
extern const int rpu_has_rsc;

#endif
