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
