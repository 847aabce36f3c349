//! Profile likelihoods against closed forms.

mod profiles;
