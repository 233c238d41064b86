//! One declaration per message. `#[derive(Message)]` on a `#[repr(C)]` struct with a `header`
//! field, or `#[derive(Layout)]` on a struct a message embeds, gives:
//!
//! - its entry in the layout table (`mole_types::layout::Layout`): every field in declaration
//!   order with its offset, size and type, and the structs it embeds, from which
//!   docs/messages.md and the Python classes are generated;
//! - the compile-time assertions of the message rules: the size written in
//!   `#[layout(size = …)]` (a layout change must be deliberate: bump the type name's version),
//!   and fields that tile the struct with no implicit padding;
//! - for a message, the `Message` impl: the header accessors, and `validate` calling the
//!   function named in `#[message(check = …)]` (none: every value is valid).
//!
//! The generated code names `::mole_types`, which mole-types itself declares as
//! `extern crate self as mole_types`.

use proc_macro::TokenStream;
use proc_macro2::TokenStream as Tokens;
use quote::quote;
use syn::{Data, DeriveInput, Expr, Fields, Ident, Path, parse_macro_input};

/// A message: `Message` and `Layout`. Needs `header: Header`, `#[layout(size = EXPR)]`, and
/// takes `#[message(check = PATH)]`, a `fn(&Self) -> Result<(), Invalid>`.
#[proc_macro_derive(Message, attributes(layout, message))]
pub fn derive_message(input: TokenStream) -> TokenStream {
    let input = parse_macro_input!(input as DeriveInput);
    expand(&input, true)
        .unwrap_or_else(syn::Error::into_compile_error)
        .into()
}

/// A struct a message embeds: `Layout` only. Needs `#[layout(size = EXPR)]`.
#[proc_macro_derive(Layout, attributes(layout))]
pub fn derive_layout(input: TokenStream) -> TokenStream {
    let input = parse_macro_input!(input as DeriveInput);
    expand(&input, false)
        .unwrap_or_else(syn::Error::into_compile_error)
        .into()
}

fn expand(input: &DeriveInput, message: bool) -> syn::Result<Tokens> {
    let name = &input.ident;
    let fields = match &input.data {
        Data::Struct(s) => match &s.fields {
            Fields::Named(f) => &f.named,
            _ => {
                return Err(syn::Error::new_spanned(
                    name,
                    "mole: a message has named fields",
                ));
            }
        },
        _ => return Err(syn::Error::new_spanned(name, "mole: a message is a struct")),
    };
    if !input.generics.params.is_empty() {
        return Err(syn::Error::new_spanned(
            &input.generics,
            "mole: a message has no type parameters",
        ));
    }
    let repr_c = input
        .attrs
        .iter()
        .any(|a| a.path().is_ident("repr") && a.parse_args::<Ident>().is_ok_and(|i| i == "C"));
    if !repr_c {
        return Err(syn::Error::new_spanned(
            name,
            "mole: a message is #[repr(C)]",
        ));
    }
    let size = attribute_value::<Expr>(input, "layout", "size")?.ok_or_else(|| {
        syn::Error::new_spanned(
            name,
            "mole: #[layout(size = …)] is required: the size a layout change must deliberately \
             update (and bump the type name's version)",
        )
    })?;
    let idents: Vec<&Ident> = fields.iter().filter_map(|f| f.ident.as_ref()).collect();
    let types: Vec<&syn::Type> = fields.iter().map(|f| &f.ty).collect();
    let names: Vec<String> = idents.iter().map(|i| i.to_string()).collect();
    let size_message = format!("mole: {name} is not the size its #[layout(size)] says");
    let tile_message = format!("mole: {name}'s fields leave padding: add an explicit `_pad`");
    let mut out = quote! {
        impl ::mole_types::layout::Layout for #name {
            fn layout() -> ::mole_types::layout::TypeLayout {
                ::mole_types::layout::TypeLayout::of::<Self>(
                    stringify!(#name),
                    vec![#(::mole_types::layout::FieldLayout::of::<#types>(
                        #names,
                        ::core::mem::offset_of!(#name, #idents),
                    )),*],
                )
            }
            fn visit_embedded(visit: &mut dyn FnMut(::mole_types::layout::TypeLayout)) {
                #(<#types as ::mole_types::layout::FieldType>::visit(visit);)*
            }
        }
        impl ::mole_types::layout::FieldType for #name {
            fn visit(visit: &mut dyn FnMut(::mole_types::layout::TypeLayout)) {
                visit(<Self as ::mole_types::layout::Layout>::layout());
                <Self as ::mole_types::layout::Layout>::visit_embedded(visit);
            }
        }
        const _: () = {
            assert!(::core::mem::size_of::<#name>() == (#size), #size_message);
            assert!(
                ::core::mem::size_of::<#name>() == 0 #(+ ::core::mem::size_of::<#types>())*,
                #tile_message
            );
        };
    };
    if message {
        if !names.iter().any(|n| n == "header") {
            return Err(syn::Error::new_spanned(
                name,
                "mole: a message starts with `header: Header` (or derive Layout for an embedded struct)",
            ));
        }
        let validate = match attribute_value::<Path>(input, "message", "check")? {
            Some(check) => quote! { #check(self) },
            None => quote! { Ok(()) },
        };
        out.extend(quote! {
            impl ::mole_types::Message for #name {
                fn header(&self) -> &::mole_types::Header {
                    &self.header
                }
                fn header_mut(&mut self) -> &mut ::mole_types::Header {
                    &mut self.header
                }
                fn validate(&self) -> ::core::result::Result<(), ::mole_types::Invalid> {
                    #validate
                }
            }
        });
    }
    Ok(out)
}

/// The value of `key` in `#[attr(key = value, …)]`, parsed as `T`; an unknown key is an error.
fn attribute_value<T: syn::parse::Parse>(
    input: &DeriveInput,
    attr: &str,
    key: &str,
) -> syn::Result<Option<T>> {
    let mut found = None;
    for a in input.attrs.iter().filter(|a| a.path().is_ident(attr)) {
        a.parse_nested_meta(|meta| {
            let value = meta.value()?;
            if meta.path.is_ident(key) {
                found = Some(value.parse::<T>()?);
            } else {
                // Another key of the same attribute: parsed by its own call.
                value.parse::<Expr>()?;
                if !known(attr, &meta.path) {
                    return Err(meta.error(format!("mole: unknown key in #[{attr}(…)]")));
                }
            }
            Ok(())
        })?;
    }
    Ok(found)
}

/// The keys each attribute takes.
fn known(attr: &str, key: &Path) -> bool {
    match attr {
        "layout" => key.is_ident("size"),
        "message" => key.is_ident("check"),
        _ => false,
    }
}

/// A setting: a struct of settings (each field a setting) or a choice (an enum of unit variants,
/// written as its serde name). Gives `mole_types::settings::Setting`: the check of every value
/// (finite numbers, the bounds of `#[setting(min = …, above = …, max = …)]`) naming the key, and
/// the keys with their doc comments, for docs/settings.md and `mole param list`.
/// `#[setting(fixed = "why")]` marks a key that cannot change while the process runs.
#[proc_macro_derive(Setting, attributes(setting))]
pub fn derive_setting(input: TokenStream) -> TokenStream {
    let input = parse_macro_input!(input as DeriveInput);
    setting::expand(&input)
        .unwrap_or_else(syn::Error::into_compile_error)
        .into()
}

mod setting {
    use proc_macro2::TokenStream as Tokens;
    use quote::quote;
    use syn::{Attribute, Data, DeriveInput, Expr, Fields, LitStr};

    /// The doc comment of an item, its lines joined by spaces.
    fn doc(attrs: &[Attribute]) -> String {
        let mut lines = Vec::new();
        for a in attrs.iter().filter(|a| a.path().is_ident("doc")) {
            if let syn::Meta::NameValue(nv) = &a.meta
                && let Expr::Lit(lit) = &nv.value
                && let syn::Lit::Str(s) = &lit.lit
            {
                lines.push(s.value().trim().to_owned());
            }
        }
        lines.join(" ")
    }

    /// `#[serde(rename = "…")]` of a field or variant, and `#[serde(rename_all = "…")]` of a
    /// container.
    fn serde_value(attrs: &[Attribute], key: &str) -> syn::Result<Option<String>> {
        let mut found = None;
        for a in attrs.iter().filter(|a| a.path().is_ident("serde")) {
            a.parse_nested_meta(|meta| {
                if meta.path.is_ident(key) {
                    found = Some(meta.value()?.parse::<LitStr>()?.value());
                } else if meta.input.peek(syn::Token![=]) {
                    meta.value()?.parse::<Expr>()?;
                }
                Ok(())
            })?;
        }
        Ok(found)
    }

    /// Whether `#[serde(key)]` (a flag, such as `skip`) is on an item.
    fn serde_flag(attrs: &[Attribute], key: &str) -> syn::Result<bool> {
        let mut found = false;
        for a in attrs.iter().filter(|a| a.path().is_ident("serde")) {
            a.parse_nested_meta(|meta| {
                if meta.path.is_ident(key) {
                    found = true;
                }
                if meta.input.peek(syn::Token![=]) {
                    meta.value()?.parse::<Expr>()?;
                }
                Ok(())
            })?;
        }
        Ok(found)
    }

    /// A field's bounds and whether it is fixed while running.
    #[derive(Default)]
    struct Rules {
        min: Option<Expr>,
        above: Option<Expr>,
        max: Option<Expr>,
        fixed: Option<String>,
    }

    fn rules(attrs: &[Attribute]) -> syn::Result<Rules> {
        let mut r = Rules::default();
        for a in attrs.iter().filter(|a| a.path().is_ident("setting")) {
            a.parse_nested_meta(|meta| {
                let value = meta.value()?;
                if meta.path.is_ident("min") {
                    r.min = Some(value.parse()?);
                } else if meta.path.is_ident("above") {
                    r.above = Some(value.parse()?);
                } else if meta.path.is_ident("max") {
                    r.max = Some(value.parse()?);
                } else if meta.path.is_ident("fixed") {
                    r.fixed = Some(value.parse::<LitStr>()?.value());
                } else {
                    return Err(meta.error(
                        "mole: #[setting(…)] takes min, above, max (bounds) and fixed (why)",
                    ));
                }
                Ok(())
            })?;
        }
        Ok(r)
    }

    fn kebab(name: &str) -> String {
        let mut out = String::new();
        for (i, c) in name.chars().enumerate() {
            if c.is_uppercase() {
                if i > 0 {
                    out.push('-');
                }
                out.extend(c.to_lowercase());
            } else {
                out.push(c);
            }
        }
        out
    }

    pub fn expand(input: &DeriveInput) -> syn::Result<Tokens> {
        let name = &input.ident;
        let s = quote! { ::mole_types::settings };
        match &input.data {
            Data::Struct(data) => {
                let Fields::Named(fields) = &data.fields else {
                    return Err(syn::Error::new_spanned(
                        name,
                        "mole: settings have named fields",
                    ));
                };
                let mut checks = Vec::new();
                let mut keys = Vec::new();
                for f in &fields.named {
                    if serde_flag(&f.attrs, "skip")? {
                        continue;
                    }
                    let ident = f.ident.as_ref().expect("named");
                    let ty = &f.ty;
                    let key = serde_value(&f.attrs, "rename")?.unwrap_or_else(|| ident.to_string());
                    let text = doc(&f.attrs);
                    let r = rules(&f.attrs)?;
                    let mut rule_text = Vec::new();
                    let mut bounds = Vec::new();
                    for (bound, symbol, test) in [
                        (&r.min, "≥", quote!(is_at_least)),
                        (&r.above, ">", quote!(is_above)),
                        (&r.max, "≤", quote!(is_at_most)),
                    ] {
                        let Some(bound) = bound else { continue };
                        // A literal bound is written as it is; a constant (`MAX_FILTER_PARTICLES`)
                        // by its value, which only the compiled code knows.
                        let value = match bound {
                            Expr::Lit(_) => {
                                let text = quote!(#bound).to_string();
                                quote!(#text)
                            }
                            _ => quote!(#bound),
                        };
                        let rule = format!("{symbol} {{}}");
                        let expected = format!("a value {symbol} {{}}");
                        rule_text.push(quote!(format!(#rule, #value)));
                        bounds.push(quote! {
                            if !#s::Bound::#test(&self.#ident, #bound) {
                                let expected = format!(#expected, #value);
                                return Err(#s::SettingError::new(&path, &expected, &self.#ident));
                            }
                        });
                    }
                    let fixed = match &r.fixed {
                        Some(why) => quote! { Some(#why) },
                        None => quote! { None },
                    };
                    checks.push(quote! {
                        {
                            let path = #s::join(at, #key);
                            <#ty as #s::Setting>::check_at(&self.#ident, &path)?;
                            #(#bounds)*
                        }
                    });
                    keys.push(quote! {
                        <#ty as #s::Setting>::keys_at(
                            &#s::join(at, #key),
                            #s::About {
                                doc: #text,
                                rule: <[::std::string::String]>::join(&[#(#rule_text),*], ", "),
                                fixed: #fixed,
                            },
                            out,
                        );
                    });
                }
                // `#[setting(check = path)]` on the struct: a check across its fields.
                let mut whole = None;
                for a in input.attrs.iter().filter(|a| a.path().is_ident("setting")) {
                    a.parse_nested_meta(|meta| {
                        if meta.path.is_ident("check") {
                            whole = Some(meta.value()?.parse::<syn::Path>()?);
                            Ok(())
                        } else {
                            Err(meta.error("mole: #[setting(…)] on a struct takes check = path"))
                        }
                    })?;
                }
                let whole = whole.map(|check| {
                    quote! { #check(self).map_err(|e| e.below(at))?; }
                });
                Ok(quote! {
                    impl #s::Setting for #name {
                        fn kind() -> ::std::string::String {
                            "table".to_owned()
                        }
                        fn check_at(&self, at: &str) -> ::core::result::Result<(), #s::SettingError> {
                            #(#checks)*
                            #whole
                            Ok(())
                        }
                        /// A table marked fixed fixes each key in it (unless one says why itself).
                        fn keys_at(at: &str, about: #s::About, out: &mut ::std::vec::Vec<#s::Key>) {
                            let first = out.len();
                            #(#keys)*
                            if let Some(why) = about.fixed {
                                for key in &mut out[first..] {
                                    key.fixed.get_or_insert_with(|| why.to_owned());
                                }
                            }
                        }
                    }
                })
            }
            Data::Enum(data) => {
                let all = serde_value(&input.attrs, "rename_all")?;
                let mut names = Vec::new();
                for v in &data.variants {
                    if !matches!(v.fields, Fields::Unit) {
                        return Err(syn::Error::new_spanned(
                            v,
                            "mole: a choice has unit variants (write Setting by hand otherwise)",
                        ));
                    }
                    let n = match serde_value(&v.attrs, "rename")? {
                        Some(n) => n,
                        None => match all.as_deref() {
                            Some("kebab-case") => kebab(&v.ident.to_string()),
                            Some("snake_case") => kebab(&v.ident.to_string()).replace('-', "_"),
                            Some("lowercase") => v.ident.to_string().to_lowercase(),
                            None => v.ident.to_string(),
                            Some(other) => {
                                return Err(syn::Error::new_spanned(
                                    name,
                                    format!("mole: rename_all = \"{other}\" is not supported"),
                                ));
                            }
                        },
                    };
                    names.push(n);
                }
                let kind = format!("one of: {}", names.join(", "));
                Ok(quote! {
                    impl #s::Setting for #name {
                        fn kind() -> ::std::string::String {
                            #kind.to_owned()
                        }
                        fn check_at(&self, _at: &str) -> ::core::result::Result<(), #s::SettingError> {
                            Ok(())
                        }
                        fn keys_at(at: &str, about: #s::About, out: &mut ::std::vec::Vec<#s::Key>) {
                            out.push(#s::Key::leaf::<Self>(at, about));
                        }
                    }
                })
            }
            Data::Union(_) => Err(syn::Error::new_spanned(
                name,
                "mole: a setting is a struct or an enum",
            )),
        }
    }
}
